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

from cli_refusals import assert_refused_in_one_line
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
    meta = {"env_id": "coursekit/PushT-v0", "episode_seeds": [0, 1]}
    save_checkpoint(DiffusionPolicy(DiffusionPolicyConfig(unet=unet, num_inference_steps=2), norms), root / "ckpt",
                    dataset_meta=meta)
    _more_originals(root, unet, norms, meta)
    return root


def _more_originals(root: Path, unet, norms, meta) -> None:
    """A flow and an ACT checkpoint, weights swapped in from another head, and four unfit data sets."""
    import json

    from coursekit.checkpoint import save_checkpoint
    from coursekit.weights_file import config_digest, file_sha256
    from coursekit.data import EpisodeDataset, MeanStdNormalizer
    from coursekit.policies.act import ACTConfig, ACTPolicy
    from coursekit.policies.flow import FlowMatchingPolicy, FlowMatchingPolicyConfig

    save_checkpoint(FlowMatchingPolicy(FlowMatchingPolicyConfig(unet=unet, num_inference_steps=2), norms), root / "flow",
                    dataset_meta=meta)
    act = ACTConfig(features="pusht_state", obs_dim=6, action_dim=2, chunk_size=8, hidden_dim=16, ff_dim=32, n_heads=2)
    save_checkpoint(ACTPolicy(act, {"obs": MeanStdNormalizer(np.full(6, 250.0), np.full(6, 100.0)),
                                    "action": MeanStdNormalizer(np.full(2, 250.0), np.full(2, 100.0))}), root / "act",
                    dataset_meta=meta)
    shutil.copytree(root / "ckpt", root / "swapped")  # a diffusion config.json over the flow weights, every sha redone
    shutil.copy(root / "flow" / "model.safetensors", root / "swapped" / "model.safetensors")
    info = json.loads((root / "swapped" / "config.json").read_text())
    info["weights"].update(sha256=file_sha256(root / "swapped" / "model.safetensors"), config_sha256=config_digest(info))
    (root / "swapped" / "config.json").write_text(json.dumps(info))
    edits = {"edited": lambda i: (i["weights"].pop("config_sha256"), i["config"].update(horizon=32)),  # Tp fits the tensors
             "illtyped": lambda i: i.update(config=["horizon", 16]),
             "nested": lambda i: i["normalizers"].update(obs=[[0.0] * 6, [512.0] * 6])}
    for name, edit in edits.items():
        shutil.copytree(root / "ckpt", root / name)
        info = json.loads((root / name / "config.json").read_text())
        edit(info)
        (root / name / "config.json").write_text(json.dumps(info))
    demos = EpisodeDataset.load(root / "demos.npz")
    action = demos["action"]
    nan = action.copy()
    nan[int(demos.episode_ends[0]) + 15, 1] = np.nan  # episode 1, step 15
    for name, new in (("wide", np.concatenate([action, action[:, :1]], axis=1)), ("text", action.astype(str)),
                      ("nan", nan)):
        EpisodeDataset({**demos.arrays, "action": new}, demos.episode_ends, demos.meta).save(root / f"{name}.npz")
    EpisodeDataset({k: v[:0] for k, v in demos.arrays.items()}, np.zeros(0, np.int64), demos.meta).save(root / "empty.npz")


@pytest.fixture
def area(tmp_path, originals):
    """The output area: a user's notes and results folder beside a dataset and a checkpoint."""
    (tmp_path / "notes.txt").write_text("my notes\n")
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "table.csv").write_text("a,b\n1,2\n")
    (tmp_path / "empty").mkdir()
    for data in ("demos", "wide", "text", "nan", "empty"):
        shutil.copy(originals / f"{data}.npz", tmp_path / f"{data}.npz")
    for ckpt in ("ckpt", "flow", "act", "swapped", "edited", "illtyped", "nested"):
        shutil.copytree(originals / ckpt, tmp_path / ckpt)
    return tmp_path




# (command line with {A} for the area, text the single error line must contain)
CASES = [
    # collect: numbers and output paths
    ("collect pusht --episodes 0 --out {A}/new.npz", "argument --episodes: must be an integer in [1, 100000], got '0'"),
    ("collect pusht --episodes 99999999999999999999 --out {A}/new.npz", "must be an integer in [1, 100000], got '99999999999999999999'"),
    ("collect pusht --episodes -3 --out {A}/new.npz", "got '-3'"),
    ("collect pusht --episodes nan --out {A}/new.npz", "got 'nan'"),
    ("collect pusht --seed -1 --out {A}/new.npz", "argument --seed: must be an integer in [0, 4294967295], got '-1'"),
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
    ("grade {A}/results --out {A}/graded --jobs 0", "argument --jobs: must be an integer in [1, 256], got '0'"),
    ("grade {A}/results --out {A}/graded --timeout inf", "argument --timeout: must be a finite number in (0, 3600], got 'inf'"),
    ("grade {A}/results --out {A}/graded --timeout 1e300", "argument --timeout: must be a finite number in (0, 3600], got '1e300'"),
    ("grade {A}/results --out {A}/graded --test-timeout nan", "got 'nan'"),
    ("grade {A}/results --out {A}/graded --memory-mb 0", "argument --memory-mb: must be an integer in [256, 1048576], got '0'"),
    ("check chunk_windows --timeout 0", "argument --timeout: must be a finite number in (0, 3600], got '0'"),
    # train: numbers, devices, flags the policy lacks, output and input paths
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --steps 0", "argument --steps: must be an integer in [1, 1000000000], got '0'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 99999999999999999999", "argument --steps: must be an integer in [1, 1000000000], got '99999999999999999999'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --batch-size 0", "argument --batch-size: must be an integer >= 1, got '0'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --checkpoint-every -1", "argument --checkpoint-every: must be a finite number in (0, 100000], got '-1'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --threads 0", "(the CPUs this process may use), got '0'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --threads 99999999999999999999", "argument --threads: must be an integer in [1, "),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --threads 100000", "(the CPUs this process may use), got '100000'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --minutes inf", "argument --minutes: must be a finite number in [0.01, 100000], got 'inf'"),
    ("train --data {A}/demos.npz --out {A}/run --minutes 1e-300", "argument --minutes: must be a finite number in [0.01, 100000], got '1e-300'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --minutes nan", "got 'nan'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --seed -1", "argument --seed: must be an integer in [0, 4294967295], got '-1'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --lr 0", "argument --lr: must be a finite number in (0, 1], got '0'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --lr 5", "argument --lr: must be a finite number in (0, 1], got '5'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --warmup-steps -1", "argument --warmup-steps: must be an integer in [0, 1000000000], got '-1'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --warmup-steps 10", "--warmup-steps 10 is more than --steps 2: the learning rate would never reach its peak; give at most 2"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --device tpu", "argument --device: must be auto, cpu, cuda, cuda:N or mps, got 'tpu'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --down-dims 16,0", "argument --down-dims: must be 1 to 6 comma-separated integers in [1, 4096] like 32,64,128, got '16,0'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --down-dims 100000", "argument --down-dims: must be 1 to 6 comma-separated integers in [1, 4096] like 32,64,128, got '100000'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --policy act --chunk-size 1000000", "argument --chunk-size: must be an integer in [1, 1000], got '1000000'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --policy act --chunk-size 500", "--chunk-size 500 is longer than the longest episode in '{A}/demos.npz' ("),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --batch-size 100000", "--batch-size 100000 is more than the 156 training samples in '{A}/demos.npz'; give at most 156"),
    # train: data unfit for the task, refused before anything is built
    ("train --data {A}/empty.npz --out {A}/run --steps 2", "--data '{A}/empty.npz' holds no episodes (0 steps): nothing to train on"),
    ("train --data {A}/wide.npz --out {A}/run --steps 2", "--data '{A}/wide.npz': 'action' has shape (170, 3), the pusht task takes actions of shape (N, 2)"),
    ("train --data {A}/text.npz --out {A}/run --steps 2", "--data '{A}/text.npz': array 'action' must hold numbers, got dtype <U"),
    ("train --data {A}/nan.npz --out {A}/run --steps 2", "--data '{A}/nan.npz': the data contains NaN at episode 1, step 15 of 'action' (column 1)"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --policy act --down-dims 16,32", "--down-dims 16,32 does not apply to --policy act"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --policy act --n-action-steps 4", "--n-action-steps 4 does not apply to --policy act"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --chunk-size 20", "--chunk-size 20 does not apply to --policy diffusion"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --policy act --horizon 32", "--horizon 32 does not apply to --policy act"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --horizon 18", "horizon 18 must be divisible by 2**(len(down_dims)-1) = 4"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --horizon 1", "argument --horizon: must be an integer in [2, 1000], got '1'"),
    ("train --data {A}/demos.npz --out {A}/run --steps 2 --vision resnet18", "--vision resnet18 applies to image features (--features pusht_image or aloha_image), not pusht_state"),
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
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --episodes 0", "argument --episodes: must be an integer in [1, 1000], got '0'"),
    ("eval {A}/ckpt --max-steps 2 --episodes 1000000", "argument --episodes: must be an integer in [1, 1000], got '1000000'"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --max-steps 0", "argument --max-steps: must be an integer in [1, 10000], got '0'"),
    ("eval {A}/ckpt --episodes 1 --max-steps 99999999999", "argument --max-steps: must be an integer in [1, 10000], got '99999999999'"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --seed-start -1", "argument --seed-start: must be an integer in [0, 4294967295], got '-1'"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --seed-start 4294967295 --episodes 2", "--seed-start 4294967295 + --episodes 2 runs past the largest seed"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --steps 0", "argument --steps: must be an integer >= 1, got '0'"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --steps 200", "--steps 200: num_inference_steps must be an int in [1, T=100], got 200"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --threads 0", "(the CPUs this process may use), got '0'"),
    ("eval {A}/ckpt --episodes 1 --max-steps 2 --threads 99999999999999999999", "(the CPUs this process may use), got '99999999999999999999'"),
    ("eval {A}/flow --episodes 1 --max-steps 2 --steps 99999999999999999999", "--steps 99999999999999999999: num_inference_steps must be an int in [1, 1000] for a flow policy, got 99999999999999999999"),
    ("eval {A}/act --episodes 1 --max-steps 2 --n-action-steps 8", "--n-action-steps 8 has no effect on '{A}/act': its 'act' policy executes by temporal ensembling"),
    ("eval {A}/ckpt --episodes 2 --max-steps 2 --record {A}/replay --record-episodes 5", "--record-episodes 5 needs --record DIR and at most --episodes (2)"),
    ("eval {A}/ckpt --episodes 2 --max-steps 2 --record-episodes 1", "--record-episodes 1 needs --record DIR"),
    ("eval {A}/swapped --episodes 1 --max-steps 2", "model.safetensors' holds the weights of a 'flow' policy but config.json says 'diffusion'"),
    ("eval {A}/edited --episodes 1 --max-steps 2", "model.safetensors' was saved with another policy_type/config/normalizers than config.json's"),
    ("eval {A}/illtyped --episodes 1 --max-steps 2", "config.json': 'config' must be a JSON object, got ['horizon', 16] (list)"),
    ("eval {A}/nested --episodes 1 --max-steps 2", "normaliser 'obs' must be a dict {'kind': ..., 'state': {stat: list}}, got"),
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
    assert_refused_in_one_line(main, [a.replace("{A}", str(area)) for a in line.split()], area, expected, capsys)


def test_debug_shows_the_traceback(area, capsys):
    with pytest.raises(ValueError, match="is not a coursekit dataset"):
        main(["collect", "pusht", "--episodes", "2", "--out", str(area / "notes.txt"), "--debug"])
    assert (area / "notes.txt").read_text() == "my notes\n"
