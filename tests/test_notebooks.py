"""Every course notebook: committed clean, and runs top to bottom through a real kernel, twice.

Notebooks run in fast mode (COURSEKIT_FAST=1) on the course's own kernel ("coursekit", which
`make setup` installs inside .venv), in two passes:

- "solutions": against the worked solutions (COURSEKIT_EXERCISES=solutions);
- "exercises": as a student meets the course, against the untouched stubs in exercises/. Every
  chapter must still run to the end without an error output, and every chapter that has an
  exercise must show the "not implemented yet" banner of
  :func:`coursekit.grading.exercise_or_reference`.

A meshcat server a notebook starts must not outlive its kernel.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from notebook_checks import banner_problems, outputs_text

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
CELL_TIMEOUT_S = int(os.environ.get("COURSEKIT_NB_CELL_TIMEOUT", "600"))
KERNEL = "coursekit"
MODES = ("solutions", "exercises")


def _ids(paths):
    return [p.stem for p in paths]


def _chapter(path: Path) -> int:
    return int(path.stem.split("_", 1)[0])


@pytest.mark.parametrize("path", NOTEBOOKS, ids=_ids(NOTEBOOKS))
def test_committed_without_outputs(path):
    nb = json.loads(path.read_text())
    dirty = [i for i, c in enumerate(nb["cells"]) if c["cell_type"] == "code" and (c.get("outputs") or c.get("execution_count"))]
    assert not dirty, f"{path.name}: cells {dirty} carry outputs; clear them before committing"
    assert nb.get("metadata", {}).get("kernelspec", {}).get("name") == KERNEL, f"{path.name}: kernelspec must be {KERNEL!r}"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=_ids(NOTEBOOKS))
def test_committed_as_the_git_filter_writes_them(path):
    """`git status` stays clean after a Run All only if stripping maps the file to itself."""
    import nbformat

    from coursekit.notebook_save import strip_notebook

    text = path.read_text()
    expected = nbformat.writes(strip_notebook(nbformat.reads(text, as_version=4)))
    expected += "" if expected.endswith("\n") else "\n"
    assert expected == text, (f"{path.name} differs from what the nbstripout filter writes; "
                                                "re-save it with nbformat.write (outputs and editor metadata stripped)")


def test_makefile_installs_the_kernel_and_the_filter():
    make = (ROOT / "Makefile").read_text()
    assert f"--name $(KERNEL)" in make and f"KERNEL := {KERNEL}" in make and "--user --name python3" not in make
    from coursekit.notebook_save import STRIP_EXTRA_KEYS

    assert "nbstripout --install" in make and " ".join(STRIP_EXTRA_KEYS) in make
    assert "--ContentsManager.pre_save_hook=coursekit.notebook_save.strip_before_save" in make
    assert any(line.startswith("nbstripout==") for line in (ROOT / "environment.txt").read_text().splitlines())


def _meshcat_servers(run_id: str) -> set[int]:
    """Meshcat servers started from this run's kernel: they inherit its COURSEKIT_NB_RUN_ID (so
    servers of other programs on a shared machine are not blamed on the notebook)."""
    import psutil

    pids = set()
    for proc in psutil.process_iter(["pid", "cmdline"]):
        cmd = " ".join(proc.info.get("cmdline") or [])
        if "meshcat.servers" in cmd or "meshcat-server" in cmd:
            try:
                if proc.environ().get("COURSEKIT_NB_RUN_ID") == run_id:
                    pids.add(proc.info["pid"])
            except (psutil.AccessDenied, psutil.NoSuchProcess, psutil.ZombieProcess):
                continue
    return pids


CAPTURES = r"\bOutput\(|\binteract(ive|_manual)?\b|\.capture\("
"""ipywidgets that capture displays into an Output widget (``interact`` does too)."""


@pytest.mark.parametrize("path", NOTEBOOKS, ids=_ids(NOTEBOOKS))
def test_no_widget_captures_displays(path):
    """A display captured by an ipywidgets.Output makes nbclient write back to the kernel, which can
    stall a headless run for its whole cell timeout (issue 22, chapter 4; the mechanism is
    test_widget_figures_never_make_a_headless_client_write_back): widget figures are
    ``coursekit.viz.FigureScrubber`` images."""
    import re

    nb = json.loads(path.read_text())
    found = [(i, m.group(0)) for i, c in enumerate(nb["cells"]) if c["cell_type"] == "code"
             for m in re.finditer(CAPTURES, "".join(c["source"]))]
    assert not found, f"{path.name}: cells capture displays into an Output widget: {found}"


def run_notebook(path: Path, monkeypatch, mode: str, fast: bool = True, env: dict[str, str] | None = None,
                 extra_cells: tuple[str, ...] = ()):
    """Execute ``path`` (plus ``extra_cells`` at the end) in a fresh "coursekit" kernel; returns the executed notebook."""
    import nbformat
    from nbclient import NotebookClient

    if fast:
        monkeypatch.setenv("COURSEKIT_FAST", "1")
    else:
        monkeypatch.delenv("COURSEKIT_FAST", raising=False)
    monkeypatch.setenv("COURSEKIT_EXERCISES", mode)
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    for key, value in (env or {}).items():
        monkeypatch.setenv(key, value)
    import uuid

    run_id = uuid.uuid4().hex
    monkeypatch.setenv("COURSEKIT_NB_RUN_ID", run_id)
    nb = nbformat.read(path, as_version=4)
    nb.cells += [nbformat.v4.new_code_cell(source) for source in extra_cells]
    client = NotebookClient(nb, timeout=CELL_TIMEOUT_S, kernel_name=KERNEL,
                            resources={"metadata": {"path": str(path.parent)}})
    try:
        client.execute()
    finally:  # COURSEKIT_NB_OUTPUT_DIR: keep the executed notebook to look at (e.g. a CI artifact)
        if os.environ.get("COURSEKIT_NB_OUTPUT_DIR"):
            out = Path(os.environ["COURSEKIT_NB_OUTPUT_DIR"])
            out.mkdir(parents=True, exist_ok=True)
            nbformat.write(nb, out / f"{path.stem}-{mode}{'' if fast else '-full'}.ipynb")
    leaked = _meshcat_servers(run_id)
    for pid in leaked:  # do not leave them running for the rest of the suite
        import psutil

        psutil.Process(pid).kill()
    assert not leaked, f"{path.name} left meshcat server processes running: {sorted(leaked)}"
    return nb


def _uses_exercises(path: Path) -> bool:
    text = path.read_text()
    return any(word in text for word in ("exercise_or_reference", "load_exercise", "coursekit.check(", "COURSEKIT_EXERCISES"))


@pytest.mark.notebook
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("path", NOTEBOOKS, ids=_ids(NOTEBOOKS))
def test_notebook_runs(path, mode, monkeypatch):
    """(The solutions pass of the chapters tests/test_browser_lab.py runs in JupyterLab is skipped
    when that test is collected and chromium is here: same kernel, same mode, same checks.)"""
    if mode == "exercises" and not _uses_exercises(path):
        pytest.skip("no exercise in this chapter: the solutions pass runs the very same code")
    nb = run_notebook(path, monkeypatch, mode)
    errors = [o for c in nb.cells for o in c.get("outputs", []) if o.get("output_type") == "error"]
    assert not errors, f"{path.name} ({mode}): error outputs {[e.get('ename') for e in errors]}"
    problems = banner_problems(nb, _chapter(path), mode)
    assert not problems, f"{path.name} ({mode}): {problems}"


@pytest.mark.notebook
def test_chapter5_full_mode_evaluates_the_policy_it_just_trained(monkeypatch):
    """Not fast mode, but a tiny budget: the freshly trained policy is evaluated beside the shipped one."""
    path = ROOT / "notebooks" / "05_diffusion_policy_pusht.ipynb"
    budget = {"demos": 4, "train_minutes": 0.05, "show_episodes": 1, "knob_episodes": 1, "knob_steps": 6,
              "eval_episodes": 2, "max_steps": 12, "replay_steps": 12}
    probe = ("import json as _json\n"
             "print('PROBE' + _json.dumps({'fast': FAST, 'steps': result.summary['steps'],\n"
             "      'trained_evaluated': [name for name, pol in contenders.items() if pol is result.policy],\n"
             "      'shipped_evaluated': [name for name, pol in contenders.items() if pol is shipped_dp],\n"
             "      'scored': list(scores)}))")
    nb = run_notebook(path, monkeypatch, "solutions", fast=False, env={"COURSEKIT_NB_BUDGET": json.dumps(budget)},
                      extra_cells=(probe,))
    text = outputs_text(nb)
    facts = json.loads(text.split("PROBE", 1)[1].splitlines()[0])
    assert facts["fast"] is False and facts["steps"] > 0
    trained = f"diffusion, trained here: {facts['steps']} steps"
    assert len(facts["trained_evaluated"]) == 1 and facts["trained_evaluated"][0].startswith(trained)
    assert facts["trained_evaluated"][0] in facts["scored"], "the trained policy was not scored in section 5.7"
    from coursekit.checkpoint import find_checkpoint, training_budget

    shipped = find_checkpoint("pusht_diffusion_state")
    if shipped is not None:  # labelled with its whole training history, read from its config
        b = training_budget(shipped)
        assert facts["shipped_evaluated"] == [f"diffusion, shipped checkpoint: {b['steps']} steps, {b['minutes']:.0f} min "
                                              f"(pusht_keypoints)"]
    assert "using the shipped checkpoint" not in text



def test_lab_saves_a_run_notebook_as_committed():
    """JupyterLab's save of a notebook after Run All (outputs, counts, editor metadata) goes through
    the pre-save hook of `make lab` and comes out byte for byte as committed: `git status` stays clean."""
    import nbformat
    from jupyter_server.services.contents.filemanager import FileContentsManager
    from traitlets.config import Config

    import tempfile

    path = ROOT / "notebooks" / "02_noise_prediction_loss.ipynb"
    committed = path.read_text()
    nb = nbformat.reads(committed, as_version=4)
    nb.metadata["language_info"] = {"name": "python", "version": "3.11.7"}
    nb.metadata["widgets"] = {"application/vnd.jupyter.widget-state+json": {"state": {}}}
    for i, cell in enumerate(c for c in nb.cells if c.cell_type == "code"):
        cell.execution_count = i + 1
        cell.outputs = [nbformat.v4.new_output("stream", name="stdout", text="x" * 1000)]
        cell.metadata["execution"] = {"iopub.status.busy": "2026-12-01T00:00:00Z"}
        cell.metadata["scrolled"] = True
    config = Config()
    config.ContentsManager.pre_save_hook = "coursekit.notebook_save.strip_before_save"
    with tempfile.TemporaryDirectory() as tmp:
        manager = FileContentsManager(root_dir=tmp, config=config)
        manager.save({"type": "notebook", "format": "json", "content": nb}, path.name)
        assert (Path(tmp) / path.name).read_text() == committed
        manager.save({"type": "notebook", "format": "json", "content": nb}, "my_notes.ipynb")  # not a course notebook
        assert "xxxx" in (Path(tmp) / "my_notes.ipynb").read_text()
