"""The command line's bad-input suite: every case is ONE line naming the bad value, exit 2, nothing touched.

Each row runs ``coursekit ...`` (in-process, through ``coursekit.cli.main``) in an output area
that already holds a user's files — notes, a results folder, a real dataset, a real checkpoint —
and asserts: exit status 2; stderr is exactly one line ``coursekit CMD: error: ...`` containing
the expected text (which names the bad value); no traceback; and every pre-existing file in the
area is byte-identical afterwards, with nothing added.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from coursekit.cli import main

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def originals(tmp_path_factory):
    """A real PushT dataset and a real (tiny) checkpoint, made once."""
    import torch

    from coursekit.checkpoint import save_checkpoint
    from coursekit.data import MinMaxNormalizer
    from coursekit.experts.pusht_planner import collect_dataset
    from coursekit.nn.unet1d import UNet1DConfig
    from coursekit.policies.diffusion import DiffusionPolicy, DiffusionPolicyConfig

    root = tmp_path_factory.mktemp("originals")
    collect_dataset(2, 0, progress=False).save(root / "demos.npz")
    torch.manual_seed(0)
    unet = UNet1DConfig(down_dims=(16, 32), kernel_size=3, n_groups=4, diffusion_step_embed_dim=16)
    norms = {"obs": MinMaxNormalizer(np.zeros(6), np.full(6, 512.0)), "action": MinMaxNormalizer(np.zeros(2), np.full(2, 512.0))}
    save_checkpoint(DiffusionPolicy(DiffusionPolicyConfig(unet=unet, num_inference_steps=2), norms), root / "ckpt",
                    dataset_meta={"env_id": "coursekit/PushT-v0", "episode_seeds": [0, 1]})
    return root


@pytest.fixture
def area(tmp_path, originals):
    """The output area: a user's notes and results folder beside a dataset and a checkpoint."""
    (tmp_path / "notes.txt").write_text("my notes\n")
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "table.csv").write_text("a,b\n1,2\n")
    (tmp_path / "empty").mkdir()
    shutil.copy(originals / "demos.npz", tmp_path / "demos.npz")
    shutil.copytree(originals / "ckpt", tmp_path / "ckpt")
    return tmp_path


def _snapshot(root: Path) -> dict[str, bytes | None]:
    return {str(p.relative_to(root)): (p.read_bytes() if p.is_file() else None) for p in sorted(root.rglob("*"))}


# (command line with {A} for the area, text the single error line must contain)
CASES = [
    # collect: numbers and output paths
    ("collect pusht --episodes 0 --out {A}/new.npz", "argument --episodes: must be an integer >= 1, got '0'"),
    ("collect pusht --episodes -3 --out {A}/new.npz", "got '-3'"),
    ("collect pusht --episodes nan --out {A}/new.npz", "got 'nan'"),
    ("collect pusht --seed -1 --out {A}/new.npz", "argument --seed: must be an integer in [0, 4.29497e+09], got '-1'"),
    ("collect pusht --seed 4294967295 --episodes 2 --out {A}/new.npz", "--seed must be in [0, 4294967294]"),
    ("collect pusht --episodes 2 --out {A}/notes.txt", "--out '{A}/notes.txt' exists and is not a coursekit dataset"),
    ("collect pusht --episodes 2 --out {A}/notes.txt --overwrite", "exists and is not a coursekit dataset"),
    ("collect pusht --episodes 2 --out {A}/results", "--out '{A}/results' is a directory"),
    ("collect pusht --episodes 2 --out {A}", "--out '{A}' is a directory"),
    ("collect pusht --episodes 2 --out {A}/notes.txt/d.npz", "'{A}/notes.txt' is a file, so nothing can be written inside it"),
    ("collect pusht --episodes 2 --out {A}/demos.npz", "--out '{A}/demos.npz' already holds a coursekit dataset; pass --overwrite"),
    ("collect pusht --episodes 2 --out {A}/ckpt", "--out '{A}/ckpt' is a directory"),
    ("collect aloha-cube --episodes 2 --action-noise 5 --out {A}/new.npz", "--action-noise is for the pusht expert only"),
    ("collect pusht --episodes 2 --action-noise ten --out {A}/new.npz", "'ten'"),
    ("collect pusht --bogus 1", "unrecognized arguments: --bogus 1"),
    ("collect cube", "argument task: invalid choice: 'cube'"),
    # demo
    ("demo --episodes 0 --out {A}/tour", "argument --episodes: must be an integer in [1, 1000], got '0'"),
    ("demo --episodes 2 --replay 2 --out {A}/tour", "--replay must index one of the 2 episodes, got 2"),
    ("demo --replay -1 --out {A}/tour", "argument --replay: must be an integer >= 0, got '-1'"),
    ("demo --out {A}/notes.txt", "--out '{A}/notes.txt' is a file"),
    # grade / check
    ("grade {A}/results --out {A}/graded --jobs 0", "argument --jobs: must be an integer >= 1, got '0'"),
    ("grade {A}/results --out {A}/graded --timeout inf", "argument --timeout: must be a finite number > 0, got 'inf'"),
    ("grade {A}/results --out {A}/graded --test-timeout nan", "got 'nan'"),
    ("grade {A}/results --out {A}/graded --memory-mb 0", "argument --memory-mb: must be an integer >= 256, got '0'"),
    ("check chunk_windows --timeout 0", "argument --timeout: must be a finite number > 0, got '0'"),
    # eval: the checkpoint argument
    ("eval {A}/missing", "checkpoint directory not found: '{A}/missing'"),
    ("eval {A}/results", "'{A}/results' has no config.json"),
    ("eval {A}/demos.npz", "checkpoint directory not found: '{A}/demos.npz'"),
]


@pytest.mark.parametrize("line,expected", CASES, ids=[c[0].replace("{A}", "A")[:60] for c in CASES])
def test_bad_input_is_one_clear_line_and_touches_nothing(area, capsys, line, expected):
    argv = [a.replace("{A}", str(area)) for a in line.split()]
    before = _snapshot(area)
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.count("\n") == 1 and err.endswith("\n"), f"not one line:\n{err}"
    assert err.startswith(f"coursekit {argv[0]}: error: "), err
    assert "Traceback" not in err
    assert expected.replace("{A}", str(area)) in err, err
    assert _snapshot(area) == before, "a pre-existing file changed, or something was written"


def test_debug_shows_the_traceback(area, capsys):
    with pytest.raises(ValueError, match="is not a coursekit dataset"):
        main(["collect", "pusht", "--episodes", "2", "--out", str(area / "notes.txt"), "--debug"])
    assert (area / "notes.txt").read_text() == "my notes\n"
