"""Every course notebook: committed without outputs, and runs top to bottom through a real kernel.

Notebooks run in fast mode (COURSEKIT_FAST=1) against the worked solutions
(COURSEKIT_EXERCISES=solutions), as CI does. A meshcat server a notebook starts must not outlive
its kernel.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
CELL_TIMEOUT_S = int(os.environ.get("COURSEKIT_NB_CELL_TIMEOUT", "600"))


def _ids(paths):
    return [p.stem for p in paths]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=_ids(NOTEBOOKS))
def test_committed_without_outputs(path):
    nb = json.loads(path.read_text())
    dirty = [i for i, c in enumerate(nb["cells"]) if c["cell_type"] == "code" and (c.get("outputs") or c.get("execution_count"))]
    assert not dirty, f"{path.name}: cells {dirty} carry outputs; clear them before committing"
    assert nb.get("metadata", {}).get("kernelspec", {}).get("name") == "python3", f"{path.name}: kernelspec must be python3"


def _meshcat_servers() -> set[int]:
    import psutil

    pids = set()
    for proc in psutil.process_iter(["pid", "cmdline"]):
        cmd = " ".join(proc.info.get("cmdline") or [])
        if "meshcat.servers" in cmd or "meshcat-server" in cmd:
            pids.add(proc.info["pid"])
    return pids


@pytest.mark.notebook
@pytest.mark.parametrize("path", NOTEBOOKS, ids=_ids(NOTEBOOKS))
def test_notebook_runs(path, monkeypatch):
    import nbformat
    from nbclient import NotebookClient

    monkeypatch.setenv("COURSEKIT_FAST", "1")
    monkeypatch.setenv("COURSEKIT_EXERCISES", os.environ.get("COURSEKIT_EXERCISES", "solutions"))
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    before = _meshcat_servers()
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(nb, timeout=CELL_TIMEOUT_S, kernel_name="python3",
                            resources={"metadata": {"path": str(path.parent)}})
    client.execute()
    leaked = _meshcat_servers() - before
    for pid in leaked:  # do not leave them running for the rest of the suite
        import psutil

        psutil.Process(pid).kill()
    assert not leaked, f"{path.name} left meshcat server processes running: {sorted(leaked)}"
