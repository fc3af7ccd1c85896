"""The student's path in a real browser: JupyterLab + headless chromium (playwright, Debian's chromium).

For chapters 0, 4 and 5: open the notebook in JupyterLab, Run All (fast mode), save, and check the
executed notebook has no error output and every cell ran; a slider moved by the test changes its
figure; a meshcat view has non-blank pixels. The teleoperation widget (chapter 1's cells, in a
scratch notebook so that the rest of chapter 1 does not have to run) is turned by synthetic mouse
events: the recorded episode's file loads, ``coursekit train`` takes it, and replaying it in a
fresh env reproduces its states exactly.

The server always stops (``lab_session.lab_server``), and the module's teardown asserts that no
process it started is left. Without chromium every test is skipped with one clear line.
"""

from __future__ import annotations

import io
import json
import time

import numpy as np
import pytest

pytestmark = pytest.mark.browser

LAUNCH_ARGS = ["--no-sandbox", "--disable-gpu-sandbox", "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
               "--disable-background-networking", "--disable-component-update", "--disable-sync"]
RUN_ALL_TIMEOUT_S = 900  # a shared, loaded CI machine; an idle 2-core one needs a few minutes for all three


@pytest.fixture(scope="module")
def browser(chromium):
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=chromium, args=LAUNCH_ARGS)
        try:
            yield b
        finally:
            b.close()


@pytest.fixture(scope="module")
def lab(browser, tmp_path_factory):
    from lab_session import ROOT, lab_server

    tmp = tmp_path_factory.mktemp("lab")
    names = ["00_setup_and_tour.ipynb", "04_samplers.ipynb", "05_diffusion_policy_pusht.ipynb"]
    with lab_server(tmp, [ROOT / "notebooks" / n for n in names],
                    env_extra={"COURSEKIT_OUTPUTS": str(tmp / "outputs")}) as server:
        server.outputs = tmp / "outputs"
        yield server
    left = server.leftover()
    assert not left, f"processes left behind by the JupyterLab server: {[(p.pid, p.name()) for p in left]}"


@pytest.fixture
def page(browser, lab):
    p = browser.new_page(viewport={"width": 1280, "height": 1000})
    try:
        yield p
    finally:
        p.close()
        lab.shutdown_kernels()


def run_notebook(page, lab, name):
    from lab_session import LabPage, error_outputs, not_run

    nb_page = LabPage(page, lab, name)
    nb_page.open()
    nb_page.run_all(RUN_ALL_TIMEOUT_S)
    nb = nb_page.save_and_read()
    assert not error_outputs(nb), f"{name}: error outputs {error_outputs(nb)}"
    assert not not_run(nb), f"{name}: cells never ran: {not_run(nb)}"
    return nb_page


def element_rgb(locator) -> np.ndarray:
    from PIL import Image

    locator.scroll_into_view_if_needed()
    return np.asarray(Image.open(io.BytesIO(locator.screenshot())).convert("RGB"), dtype=np.float64)


def assert_meshcat_draws(page) -> None:
    frames = page.locator(".jp-OutputArea-output iframe")
    assert frames.count() >= 1, "no meshcat iframe in the outputs"
    frame = frames.first
    frame.scroll_into_view_if_needed()
    deadline = time.monotonic() + 60
    while True:  # WebGL on the CPU (SwiftShader) takes a moment to draw the first frame
        img = element_rgb(frame)
        colours = len(np.unique((img // 16).reshape(-1, 3), axis=0))
        if (img.std() > 10 and colours > 20) or time.monotonic() > deadline:
            break
        time.sleep(1.0)
    assert img.std() > 10 and colours > 20, f"meshcat view looks blank (std {img.std():.1f}, {colours} colours)"


def scrub_changes_figure(page, cell_has: str, images: str) -> None:
    """Press ArrowRight on the first slider of the cell that holds ``cell_has``: its figure changes."""
    cell = page.locator(f".jp-CodeCell:has({cell_has})").first
    cell.scroll_into_view_if_needed()
    imgs = cell.locator(images)
    before = imgs.first.get_attribute("src")
    assert before, "the widget shows no figure"
    handle = cell.locator(".noUi-handle").first
    for _attempt in range(3):  # keyboard focus can be lost to a re-render: focus and press again
        handle.focus()
        for _ in range(3):
            handle.press("ArrowRight")
        deadline = time.monotonic() + 20
        while imgs.first.get_attribute("src") == before and time.monotonic() < deadline:
            time.sleep(0.3)
        if imgs.first.get_attribute("src") != before:
            return
    value = cell.locator(".widget-readout").first.inner_text()
    raise AssertionError(f"moving the slider (readout now {value!r}) did not change the figure")


def test_chapter0_runs_and_its_meshcat_views_draw(page, lab):
    run_notebook(page, lab, "00_setup_and_tour.ipynb")
    assert_meshcat_draws(page)


def test_chapter4_runs_and_the_denoising_scrubber_moves_its_figure(page, lab):
    run_notebook(page, lab, "04_samplers.ipynb")
    scrub_changes_figure(page, ".ck-scrubber", ".ck-scrub-figure")


def test_chapter5_runs_the_ta_scrubber_moves_and_meshcat_draws(page, lab):
    run_notebook(page, lab, "05_diffusion_policy_pusht.ipynb")
    scrub_changes_figure(page, ".ck-scrubber", ".ck-scrub-figure")
    assert_meshcat_draws(page)


def _teleop_notebook(lab) -> str:
    """Chapter 1's teleoperation cell, verbatim, after the two names it uses from earlier cells."""
    from lab_session import ROOT

    ch1 = json.loads((ROOT / "notebooks" / "01_pusht_and_multimodality.ipynb").read_text())
    cell = next(c for c in ch1["cells"] if c.get("id") == "teleop-widget")
    head = "import os\nfrom coursekit.experts.pusht_planner import TWO_WAY_START"
    nb = {"cells": [{"cell_type": "code", "execution_count": None, "id": f"c{i}", "metadata": {}, "outputs": [],
                     "source": src} for i, src in enumerate([head, "".join(cell["source"])])],
          "metadata": {"kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"}},
          "nbformat": 4, "nbformat_minor": 5}
    (lab.root / "teleop.ipynb").write_text(json.dumps(nb))
    return "teleop.ipynb"


def test_teleop_widget_records_a_mouse_drag_that_trains_and_replays(page, lab, tmp_path):
    from coursekit.cli import main
    from coursekit.data.episodes import EpisodeDataset
    from coursekit.experts.pusht_planner import TWO_WAY_START
    from coursekit.teleop import replay

    run_notebook(page, lab, _teleop_notebook(lab))
    canvas = page.locator(".ck-teleop-canvas")
    canvas.scroll_into_view_if_needed()
    page.locator(".ck-teleop-start").click()
    readout = page.locator(".ck-teleop-readout")
    deadline = time.monotonic() + 60  # the kernel answers Start by setting "recording"; wait for it
    while "recording" not in readout.inner_text() and time.monotonic() < deadline:
        time.sleep(0.2)
    box = canvas.bounding_box()
    scale = box["width"] / 512.0

    def screen(x, y):
        return box["x"] + x * scale, box["y"] + y * scale

    # press on the pusher, then drag round below the T and push up into it, slowly enough that
    # the 10 Hz ticks see many different targets
    ax, ay = TWO_WAY_START[:2]
    path = [(ax + 10 * i, ay + 8 * i) for i in range(12)] + [(220 + 8 * i, 352 - 4 * i) for i in range(12)]
    page.mouse.move(*screen(ax, ay))
    page.mouse.down()
    for x, y in path:
        page.mouse.move(*screen(x, y), steps=2)
        time.sleep(0.12)
    page.mouse.up()
    deadline = time.monotonic() + 60
    while "step 0 " in readout.inner_text() and time.monotonic() < deadline:
        time.sleep(0.3)
    time.sleep(1.0)
    page.locator(".ck-teleop-stop").click()
    deadline = time.monotonic() + 30
    while "kept 1" not in readout.inner_text() and time.monotonic() < deadline:
        time.sleep(0.3)
    assert "kept 1" in readout.inner_text(), readout.inner_text()

    path_file = lab.outputs / "data" / "pusht_teleop.npz"
    data = EpisodeDataset.load(path_file)
    assert data.n_episodes == 1 and data.meta["expert"] == "coursekit.teleop"
    actions = data["action"]
    assert len(actions) >= 10, f"only {len(actions)} control steps were recorded"
    assert len(np.unique(np.round(actions), axis=0)) >= 5, "the mouse drag did not reach the recorder"
    np.testing.assert_array_equal(replay(data, 0), data["state"])  # a fresh env reproduces it exactly
    out = tmp_path / "ckpt"
    assert main(["train", "--data", str(path_file), "--steps", "2", "--out", str(out), "--threads", "1",
                 "--no-progress", "--down-dims", "16,32"]) == 0
    assert (out / "config.json").is_file()


def test_the_server_and_its_kernels_stop_even_when_a_test_fails(tmp_path):
    """The guarantee every test above relies on: an exception inside the session still stops
    the server, and the kernel it started (a process in a session of its own) with it."""
    from lab_session import lab_server

    seen = {}
    with pytest.raises(RuntimeError, match="a failing test"):
        with lab_server(tmp_path, []) as server:
            seen["server"] = server
            kernel = server.api("/api/kernels", method="POST")
            deadline = time.monotonic() + 60
            while not server.descendants() and time.monotonic() < deadline:
                time.sleep(0.2)
            assert server.descendants(), f"kernel {kernel} started no process"
            raise RuntimeError("a failing test")
    server = seen["server"]
    assert server.proc.poll() is not None
    assert not server.leftover(), f"left behind: {server.leftover()}"
