"""The package itself: cheap import, lazy submodules, registered gym ids, CLI, glossary."""

from __future__ import annotations

import subprocess
import sys

import pytest


def _run(code: str) -> str:
    return subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout


def test_import_is_lazy():
    out = _run("import sys, coursekit; print(sorted(m for m in ('torch','mujoco','meshcat','pymunk') if m in sys.modules))")
    assert out.strip() == "[]"


def test_pusht_alone_does_not_pull_torch_or_mujoco():
    out = _run("import sys, coursekit.envs.pusht; print(sorted(m for m in ('torch','mujoco','meshcat') if m in sys.modules))")
    assert out.strip() == "[]"


def test_gym_ids_registered():
    import gymnasium

    import coursekit  # noqa: F401

    for env_id in ("coursekit/PushT-v0", "coursekit/AlohaTransferCube-v0", "coursekit/AlohaInsertion-v0"):
        assert env_id in gymnasium.registry


def test_every_generative_head_is_public_beside_the_others():
    """``coursekit.flow`` is reached like ``coursekit.diffusion`` (lazily, the very module)."""
    import importlib

    import coursekit

    for name in ("diffusion", "flow", "policies", "train", "training_log"):
        assert name in dir(coursekit)
        assert getattr(coursekit, name) is importlib.import_module(f"coursekit.{name}")


def test_unknown_attribute():
    import coursekit

    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        coursekit.nothing  # noqa: B018


def test_cli_help_lists_commands():
    out = subprocess.run([sys.executable, "-m", "coursekit.cli", "--help"], capture_output=True, text=True, check=True).stdout
    assert "collect" in out


def test_cli_bad_input_is_a_clear_error(tmp_path):
    res = subprocess.run([sys.executable, "-m", "coursekit.cli", "collect", "pusht", "--episodes", "0",
                          "--out", str(tmp_path / "x.npz")], capture_output=True, text=True)
    assert res.returncode == 2
    assert res.stderr == ("coursekit collect: error: argument --episodes: must be an integer in [1, 100000], got '0' "
                          "(see `coursekit collect --help`)\n")
    assert not (tmp_path / "x.npz").exists()


def test_glossary_matches_readme():
    from pathlib import Path

    from coursekit.glossary import GLOSSARY

    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    for symbol in ("To", "Tp", "Ta", "k", "beta"):
        name = GLOSSARY[symbol][0]
        assert f"| {symbol} | `{name}` |" in readme, f"README glossary lacks {symbol} -> {name}"


def test_resolve_device():
    torch = pytest.importorskip("torch")
    from coursekit.device import resolve_device

    assert resolve_device("cpu") == torch.device("cpu")
    assert resolve_device("auto").type in {"cpu", "cuda", "mps"}
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="'cuda'"):
            resolve_device("cuda")
    with pytest.raises(ValueError, match="42"):
        resolve_device(42)
