"""The student's path in a real browser: JupyterLab + headless chromium (playwright, Debian's chromium).

For chapters 0, 4 and 5: open the notebook in JupyterLab, Run All (fast mode), save, and check the
executed notebook has no error output and every cell ran; a slider moved by the test changes its
figure; a meshcat view has non-blank pixels. The teleoperation widget (chapter 1's cells, in a
scratch notebook so that the rest of chapter 1 does not have to run) is turned by synthetic mouse
events: the recorded episode's file loads, ``coursekit train`` takes it, and replaying it in a
fresh env reproduces its states exactly; a press on the pusher where it is drawn and a drag to two
points, in a wide and a narrow notebook, record the world points under the mouse.

The server always stops (``lab_session.lab_server``), and the module's teardown asserts that no
process it started is left. Without chromium every test is skipped with one clear line.
"""

from __future__ import annotations

import io
import json
import re
import time
from pathlib import Path

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
    """Run All in JupyterLab; the saved notebook passes what tests/test_notebooks.py checks of an
    nbclient run (which then skips this chapter's solutions pass, see tests/conftest.py)."""
    from lab_session import LabPage, error_outputs, exercise_mode, not_run
    from notebook_checks import banner_problems

    nb_page = LabPage(page, lab, name)
    nb_page.open()
    nb_page.run_all(RUN_ALL_TIMEOUT_S)
    nb = nb_page.save_and_read()
    assert not error_outputs(nb), f"{name}: error outputs {error_outputs(nb)}"
    assert not not_run(nb), f"{name}: cells never ran: {not_run(nb)}"
    mode = exercise_mode()  # what the lab's kernels ran
    if mode in ("solutions", "exercises") and name.split("_", 1)[0].isdigit():  # a course chapter
        problems = banner_problems(nb, int(name.split("_", 1)[0]), mode)
        assert not problems, f"{name} ({mode}): {problems}"
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


@pytest.mark.lab_runs("00_setup_and_tour")
def test_chapter0_runs_and_its_meshcat_views_draw(page, lab):
    run_notebook(page, lab, "00_setup_and_tour.ipynb")
    assert_meshcat_draws(page)


@pytest.mark.lab_runs("04_samplers")
def test_chapter4_runs_and_the_denoising_scrubber_moves_its_figure(page, lab):
    run_notebook(page, lab, "04_samplers.ipynb")
    scrub_changes_figure(page, ".ck-scrubber", ".ck-scrub-figure")


@pytest.mark.lab_runs("05_diffusion_policy_pusht")
def test_chapter5_runs_the_ta_scrubber_moves_and_meshcat_draws(page, lab):
    run_notebook(page, lab, "05_diffusion_policy_pusht.ipynb")
    scrub_changes_figure(page, ".ck-scrubber", ".ck-scrub-figure")
    assert_meshcat_draws(page)


def _teleop_notebook(lab, name: str = "teleop.ipynb", outputs: Path | None = None) -> str:
    """Chapter 1's teleoperation cell, verbatim, after the two names it uses from earlier cells
    (and, given ``outputs``, a ``COURSEKIT_OUTPUTS`` of its own, so its recording file is its own)."""
    from lab_session import ROOT

    ch1 = json.loads((ROOT / "notebooks" / "01_pusht_and_multimodality.ipynb").read_text())
    cell = next(c for c in ch1["cells"] if c.get("id") == "teleop-widget")
    head = "import os\nfrom coursekit.experts.pusht_planner import TWO_WAY_START"
    if outputs is not None:
        head += f"\nos.environ['COURSEKIT_OUTPUTS'] = {str(outputs)!r}"
    nb = {"cells": [{"cell_type": "code", "execution_count": None, "id": f"c{i}", "metadata": {}, "outputs": [],
                     "source": src} for i, src in enumerate([head, "".join(cell["source"])])],
          "metadata": {"kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"}},
          "nbformat": 4, "nbformat_minor": 5}
    (lab.root / name).write_text(json.dumps(nb))
    return name


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


# A wide notebook, and one whose output area is narrower than the canvas's 400 px (shown at 388 here)
TELEOP_VIEWPORTS = ((1400, 1000), (820, 900))
TELEOP_TOL = 3.0  # world units; one screen px is 512 / 400 = 1.28 of them on the default canvas
CONTENT_BOX_JS = """c => { const r = c.getBoundingClientRect();
  const sx = r.width / c.offsetWidth, sy = r.height / c.offsetHeight;
  return [r.left + c.clientLeft * sx, r.top + c.clientTop * sy, c.clientWidth * sx, c.clientHeight * sy]; }"""


def _wait_readout(readout, predicate, what: str, timeout_s: float = 60) -> str:
    deadline = time.monotonic() + timeout_s
    while not predicate(text := readout.inner_text()) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert predicate(text), f"waited {timeout_s} s for {what}; the readout says {text!r}"
    return text


def _steps(text: str) -> int:
    return int(re.search(r"step (\d+)", text).group(1))


def _drawn_view(canvas):
    """Where the canvas's picture lies on screen: its content box (left, top, width, height) in
    viewport px, and the centroid (x, y) and width of the pusher as drawn there (its pixels)."""
    from coursekit.envs.pusht_render import AGENT_COLOR

    img = element_rgb(canvas)  # the border box, one image px per CSS px (device scale 1)
    frame = canvas.bounding_box()
    content = canvas.evaluate(CONTENT_BOX_JS)
    ys, xs = np.nonzero(np.all(np.abs(img - np.array(AGENT_COLOR)) < 30, axis=-1))
    assert len(xs) > 20, "the pusher is not drawn on the canvas"
    centroid = (frame["x"] + xs.mean() + 0.5, frame["y"] + ys.mean() + 0.5)
    return content, centroid, xs.max() - xs.min() + 1


def _record_presses(page, world_points, episode: int):
    """Start, press on the drawn pusher, drag to each world point (a few control steps at each),
    release, Stop. Returns the screen points the mouse was at, their world points (through the
    canvas's content box), the drawn pusher and its width in px."""
    canvas, readout = page.locator(".ck-teleop-canvas"), page.locator(".ck-teleop-readout")
    page.locator(".ck-teleop-start").click()
    _wait_readout(readout, lambda t: "recording" in t, "Start")
    (left, top, width, height), pusher, pusher_px = _drawn_view(canvas)
    screen = [pusher] + [(left + x * width / 512, top + y * height / 512) for x, y in world_points]
    under = [((sx - left) * 512 / width, (sy - top) * 512 / height) for sx, sy in screen]
    for i, (sx, sy) in enumerate(screen):
        page.mouse.move(sx, sy)
        if i == 0:
            page.mouse.down()
        reached = _steps(readout.inner_text())
        _wait_readout(readout, lambda t, n=reached: _steps(t) >= n + 4, "four control steps")
    page.mouse.up()
    page.locator(".ck-teleop-stop").click()
    _wait_readout(readout, lambda t: f"kept {episode + 1}" in t, f"episode {episode} to be kept")
    return screen, np.array(under), (pusher_px, width)


def test_teleop_targets_land_under_the_mouse_at_two_notebook_widths(page, lab):
    """Press on the pusher where it is drawn and drag to two points, in a wide and a narrow
    notebook: every recorded target is the world point under the mouse, within a few pixels.
    (The canvas once stretched to its button bar's width, which changes with the status text,
    while the mouse was read as 400 px: a press on the pusher at (100, 256) sent it to (162, 412).)"""
    from coursekit.data.episodes import EpisodeDataset
    from coursekit.envs import pusht_geometry as geo

    page.set_viewport_size({"width": TELEOP_VIEWPORTS[0][0], "height": TELEOP_VIEWPORTS[0][1]})
    run_notebook(page, lab, _teleop_notebook(lab, "teleop_mapping.ipynb", lab.outputs / "mapping"))
    world_points = [(150.0, 120.0), (420.0, 170.0)]
    for episode, (vw, vh) in enumerate(TELEOP_VIEWPORTS):
        page.set_viewport_size({"width": vw, "height": vh})
        screen, under, (pusher_px, width) = _record_presses(page, world_points, episode)
        data = EpisodeDataset.load(lab.outputs / "mapping" / "data" / "pusht_teleop.npz")
        assert data.n_episodes == episode + 1
        ep = data.episode(episode)
        where = f"viewport {vw}x{vh}, canvas drawn {width:.0f} px wide"
        # the test's own reading of the screen: the pusher is drawn where the state says it is
        np.testing.assert_allclose(under[0], ep["state"][0, :2], atol=TELEOP_TOL, err_msg=where)
        assert abs(pusher_px - 2 * geo.AGENT_RADIUS * width / 512) <= 3, (where, pusher_px)
        np.testing.assert_allclose(under[1:], world_points, atol=TELEOP_TOL, err_msg=where)
        # every recorded target is one of the three points under the mouse, in the order visited
        actions = ep["action"]
        dist = np.linalg.norm(actions[:, None, :] - under[None, :, :], axis=-1)  # (T, 3)
        nearest = dist.argmin(axis=1)
        off = dist.min(axis=1) > TELEOP_TOL
        assert not off.any(), (f"{where}: targets {np.round(actions[off][:5], 1).tolist()} are not under the mouse "
                               f"(it was at world {np.round(under, 1).tolist()})")
        assert nearest[0] == 0 and set(nearest) == {0, 1, 2} and np.all(np.diff(nearest) >= 0), (where, nearest)


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


@pytest.mark.parametrize(("cells", "says"), [
    (["print('before')", "raise ValueError('boom in the second cell')", "print('never')"], "boom in the second cell"),
    (["print('before')", "import os\nos._exit(3)", "print('never')"], "restart"),
], ids=["a cell raises", "the kernel dies"])
def test_run_all_that_stops_early_fails_at_once_and_says_why(browser, tmp_path, cells, says):
    """JupyterLab drops its queue when a cell raises or the kernel dies: the harness must report
    that within seconds (with the error, the kernel's fate and the server log), not wait out
    RUN_ALL_TIMEOUT_S on cells that will never run (CI once spent 900 s so on chapter 0)."""
    import nbformat
    from lab_session import LabPage, RunAllStopped, lab_server

    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(c) for c in cells])
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    path = tmp_path / "stops.ipynb"
    nbformat.write(nb, path)
    with lab_server(tmp_path / "srv", [path]) as server:
        page = browser.new_page(viewport={"width": 1280, "height": 1000})
        try:
            lab_page = LabPage(page, server, path.name)
            lab_page.open()
            t0 = time.monotonic()
            with pytest.raises(RunAllStopped) as stopped:
                lab_page.run_all(RUN_ALL_TIMEOUT_S)
            waited = time.monotonic() - t0
        finally:
            page.close()
    assert waited < 120, f"Run All's stop was noticed only after {waited:.0f} s"
    assert says in str(stopped.value).lower() or says in str(stopped.value), str(stopped.value)[:2000]


def test_open_waits_for_the_real_kernel_and_names_a_dialog_at_once(browser, tmp_path):
    """``LabPage.open`` returns only once the notebook's kernel is connected and idle (the toolbar's
    indicator reads 'idle' before any kernel exists: a Run All issued then opened "Select Kernel" in CI),
    and a dialog in its place (here: the notebook asks for a kernel this server lacks) fails at once."""
    import nbformat
    from lab_session import KERNEL_STATE_JS, LabPage, lab_server

    good, bad = tmp_path / "good.ipynb", tmp_path / "bad.ipynb"
    for path, kernel in ((good, "python3"), (bad, "no-such-kernel")):
        nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("print('hi')")])
        nb.metadata["kernelspec"] = {"name": kernel, "display_name": kernel, "language": "python"}
        nbformat.write(nb, path)
    with lab_server(tmp_path / "srv", [good, bad]) as server:
        page = browser.new_page(viewport={"width": 1280, "height": 1000})
        try:
            LabPage(page, server, good.name).open()
            state = page.evaluate(KERNEL_STATE_JS)
            assert state["connection"] == "connected" and state["status"] == "idle", state
            t0 = time.monotonic()
            with pytest.raises(RuntimeError, match="dialog is open after opening") as opened:
                LabPage(page, server, bad.name).open()
            waited = time.monotonic() - t0
        finally:
            page.close()
    assert "Select Kernel" in str(opened.value), str(opened.value)[:1000]
    assert waited < 60, f"the dialog was noticed only after {waited:.0f} s"
