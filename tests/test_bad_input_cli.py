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
    ("demo --out {A}/notes.txt", "--out '{A}/notes.txt' exists and is a file, not a folder"),
    # grade / check
    ("grade {A}/results --out {A}/graded --jobs 0", "argument --jobs: must be an integer >= 1, got '0'"),
    ("grade {A}/results --out {A}/graded --timeout inf", "argument --timeout: must be a finite number > 0, got 'inf'"),
    ("grade {A}/results --out {A}/graded --test-timeout nan", "got 'nan'"),
    ("grade {A}/results --out {A}/graded --memory-mb 0", "argument --memory-mb: must be an integer >= 256, got '0'"),
    ("check chunk_windows --timeout 0", "argument --timeout: must be a finite number > 0, got '0'"),
    # train: numbers, devices, flags the policy lacks, output and input paths
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --steps 0", "argument --steps: must be an integer >= 1, got '0'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --batch-size 0", "argument --batch-size: must be an integer >= 1, got '0'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --checkpoint-every -1", "argument --checkpoint-every: must be a finite number > 0, got '-1'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --threads 0", "argument --threads: must be an integer >= 1, got '0'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --minutes inf", "argument --minutes: must be a finite number > 0, got 'inf'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --minutes nan", "got 'nan'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --seed -1", "argument --seed: must be an integer in [0, 4.29497e+09], got '-1'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --lr 0", "argument --lr: must be a finite number > 0, got '0'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --warmup-steps -1", "argument --warmup-steps: must be an integer >= 0, got '-1'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --device tpu", "argument --device: must be auto, cpu, cuda, cuda:N or mps, got 'tpu'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --down-dims 16,0", "argument --down-dims: must be comma-separated positive integers like 32,64,128, got '16,0'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --policy act --down-dims 16,32", "--down-dims 16,32 does not apply to --policy act"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --policy act --n-action-steps 4", "--n-action-steps 4 does not apply to --policy act"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --chunk-size 20", "--chunk-size 20 does not apply to --policy diffusion"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --vision resnet18", "--vision resnet18 applies to image features (--features pusht_image), not pusht_state"),
    ("train --data {A}/demos.npz --out {A}/run", "give a budget: --minutes M and/or --steps N"),
    ("train --data {A}/demos.npz --steps 2 --out {A}/results", "--out '{A}/results' exists and is not a coursekit run folder (it holds 'table.csv', which a run never writes)"),
    ("train --data {A}/demos.npz --steps 2 --out {A}/results --overwrite", "is not a coursekit run folder"),
    ("train --data {A}/demos.npz --steps 2 --out {A}/notes.txt", "--out '{A}/notes.txt' exists and is a file"),
    ("train --data {A}/demos.npz --steps 2 --out {A}/demos.npz", "--out '{A}/demos.npz' is the input '{A}/demos.npz'"),
    ("train --data {A}/demos.npz --steps 2 --out {A}/demos.npz/run", "is inside the input '{A}/demos.npz'"),
    ("train --data {A}/demos.npz --steps 2 --out {A}", "--out '{A}' contains the input '{A}/demos.npz'"),
    ("train --data {A}/demos.npz --steps 2 --out {A}/notes.txt/run", "'{A}/notes.txt' is a file, so nothing can be written inside it"),
    ("train --data {A}/demos.npz --steps 2 --out {A}/ckpt", "--out '{A}/ckpt' already holds a coursekit run folder; pass --overwrite"),
    ("train --data {A}/demos.npz --steps 2 --out {A}/ckpt --init-from {A}/ckpt --overwrite", "is the input '{A}/ckpt'"),
    ("train --data {A}/missing.npz --steps 2 --out {A}/run", "dataset file not found: '{A}/missing.npz'"),
    ("train --data {A}/notes.txt --steps 2 --out {A}/run", "'{A}/notes.txt' is not a coursekit dataset"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --init-from {A}/results", "'{A}/results' has no config.json"),
    # eval: numbers, flags the checkpoint's policy lacks, output paths
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --episodes 0", "argument --episodes: must be an integer >= 1, got '0'"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --max-steps 0", "argument --max-steps: must be an integer >= 1, got '0'"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --seed-start -1", "argument --seed-start: must be an integer in [0, 4.29497e+09], got '-1'"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --seed-start 4294967295 --episodes 2", "--seed-start 4294967295 + --episodes 2 runs past the largest seed"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --steps 0", "argument --steps: must be an integer >= 1, got '0'"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --steps 200", "--steps 200: num_inference_steps must be an int in [1, T=100], got 200"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --threads 0", "argument --threads: must be an integer >= 1, got '0'"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --device tpu", "got 'tpu'"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --no-ensembling", "--no-ensembling does not apply to '{A}/ckpt': it holds a 'diffusion' policy"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --ensemble-decay 0.1", "--ensemble-decay 0.1 does not apply to '{A}/ckpt'"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --n-action-steps 99", "n_action_steps=99"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --json {A}", "--json '{A}' is a directory"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --json {A}/notes.txt", "--json '{A}/notes.txt' exists and is not a coursekit evaluation summary"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --json {A}/ckpt/eval.json", "--json '{A}/ckpt/eval.json' is inside the input '{A}/ckpt'"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --record {A}/results", "--record '{A}/results' already exists and holds 'table.csv': choose a new or empty folder"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --record {A}/notes.txt", "exists and is a file"),
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
