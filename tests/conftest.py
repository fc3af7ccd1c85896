"""Fixtures shared by test modules (opt in with ``pytestmark = pytest.mark.usefixtures(...)``)."""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path

import pytest

# MuJoCo picks its OpenGL backend once, when first imported. A test module that runs
# `pytest.importorskip("mujoco")` before anything imports coursekit.envs.aloha (which sets this
# default itself) would otherwise lock in GLFW, which needs a display, and every later offscreen
# render fails. Same default as coursekit.envs.aloha and .ci/run, so plain `make test` works too.
os.environ.setdefault("MUJOCO_GL", "egl")

# Property-based tests draw their examples deterministically (same examples every run, no example
# database): a CI run cannot fail on a draw the previous run did not make. To hunt for new
# failures, run with HYPOTHESIS_PROFILE=explore (random draws), then add what it finds as a case.
try:
    from hypothesis import settings as _hypothesis_settings

    _hypothesis_settings.register_profile("deterministic", derandomize=True, database=None)
    _hypothesis_settings.register_profile("explore", derandomize=False)
    _hypothesis_settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "deterministic"))
except ImportError:  # the grading image has no hypothesis; its tests do not use it
    pass


@pytest.fixture
def one_torch_thread():
    """Small ops: one thread is as fast, and immune to oversubscription on a shared CPU."""
    torch = pytest.importorskip("torch")
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture(scope="module")
def chromium(request):
    """Path of Debian's headless chromium; without it the requesting module's browser tests skip, loudly."""
    from headless_chromium import find_chromium

    path = find_chromium()
    if path is None:
        reason = (f"!!! HEADLESS CHROMIUM IS NOT INSTALLED: the real-browser tests of {request.module.__name__} are "
                  "SKIPPED. Install it with `apt-get install -y chromium` (`make test` does this as root). !!!")
        warnings.warn(reason, stacklevel=1)
        pytest.skip(reason)
    return path


TINY = {"diffusion": ["--down-dims", "16,32"], "regression": ["--down-dims", "16,32"], "flow": ["--down-dims", "16,32"],
        "act": ["--chunk-size", "8"]}  # at most the reach task's shortest demonstration (9 steps)
"""`coursekit train` flags that make each policy type tiny (a type without an entry trains at its default size)."""
SAMPLES = {"diffusion": ["--steps", "2"], "flow": ["--steps", "2"]}
"""`coursekit eval` flags of the policy types that sample: two denoising / integration steps."""


def _train_then_eval(policy: str, data: Path, folder: Path, max_steps: int = 4, train_steps: int = 3, episodes: int = 1,
                     eval_args: tuple[str, ...] = ()) -> tuple[dict, dict]:
    from coursekit.cli import main

    run = folder / "run"
    assert main(["train", "--policy", policy, "--data", str(data), "--steps", str(train_steps), "--batch-size", "4",
                 "--warmup-steps", "1", "--out", str(run), "--threads", "1", "--no-progress", *TINY.get(policy, [])]) == 0
    out = folder / "eval.json"
    assert main(["eval", str(run), "--episodes", str(episodes), "--max-steps", str(max_steps), "--threads", "1",
                 "--no-progress", "--json", str(out), *SAMPLES.get(policy, []), *eval_args]) == 0
    return json.loads((run / "config.json").read_text()), json.loads(out.read_text())


@pytest.fixture
def train_then_eval():
    """`coursekit train` (tiny, a few steps) into ``folder/run``, then `coursekit eval` on a short episode:
    returns (the checkpoint's config.json, the eval summary)."""
    return _train_then_eval


# `make test` runs the suite on two workers (pytest-xdist, ``--dist loadscope``, refined below). A
# module whose tests share a costly module-scoped fixture (a JupyterLab server, the graded attack
# corpus, a trained tiny policy) stays on one worker, so that the fixture is built once; the notebook
# runs and the shipped-checkpoint reproductions, each independent and long, spread over both. The
# longest modules go first (with --no-loadscope-reorder), so that no worker is left with a long one
# at the end. (Not ``--dist loadgroup`` with xdist_group marks: with pytest 9.2 those marks are
# silently ignored, pytest-dev/pytest-xdist#1386.)
SPREAD = {"test_notebooks.py", "test_shipped_checkpoints.py"}
"""Modules whose tests are scheduled one by one (no shared fixture worth keeping together)."""
LONGEST_FIRST = ("test_notebooks.py", "test_shipped_checkpoints.py", "test_grading_attacks.py", "test_browser_lab.py",
                 "test_kill.py", "test_grading_exercises.py", "test_grading_corpus.py")
"""Modules started first (about their order of cost in ``make test``); the rest follow in file order."""


def _skip_notebook_runs_done_in_lab(items) -> None:
    """A chapter that a collected ``lab_runs`` test runs in JupyterLab (real kernel, fast mode, the
    same error and banner checks) is not run again through nbclient in the same mode: skip that
    pass of tests/test_notebooks.py. Only when the browser test can run (chromium, playwright)."""
    import importlib.util

    from headless_chromium import find_chromium

    in_lab = {m.args[0] for item in items for m in item.iter_markers("lab_runs")}
    if not in_lab or find_chromium() is None or importlib.util.find_spec("playwright") is None:
        return
    mode = os.environ.get("COURSEKIT_EXERCISES", "exercises")
    for item in items:
        spec = getattr(item, "callspec", None)
        if item.originalname == "test_notebook_runs" and spec is not None and spec.params.get("mode") == mode \
                and spec.params["path"].stem in in_lab:
            item.add_marker(pytest.mark.skip(reason="run in JupyterLab by tests/test_browser_lab.py (same mode and checks)"))


@pytest.hookimpl(trylast=True)  # after -m / -k deselection: only browser tests that will run count
def pytest_collection_modifyitems(config, items):
    def rank(item) -> int:
        name = item.path.name
        return LONGEST_FIRST.index(name) if name in LONGEST_FIRST and item.path.parent.name == "tests" else len(LONGEST_FIRST)

    items.sort(key=rank)  # stable: every module stays contiguous, in its own order
    _skip_notebook_runs_done_in_lab(items)


@pytest.hookimpl(optionalhook=True)  # a hook of pytest-xdist: only called when it is installed
def pytest_xdist_make_scheduler(config, log):
    """With ``--dist loadscope``: one work unit per module, except the modules of :data:`SPREAD` (one per test)."""
    if config.getoption("dist") != "loadscope":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class ModuleScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            return nodeid if Path(module).name in SPREAD else module

    return ModuleScheduling(config, log)
