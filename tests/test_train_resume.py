"""A training run killed and resumed from its state file gives the bytes of an uninterrupted run."""

from __future__ import annotations

import pytest
import torch

import coursekit.train_state as train_state
from coursekit.policies.factory import make_policy
from coursekit.train import TrainConfig, train
from test_train import TINY, synthetic_pusht

pytestmark = pytest.mark.usefixtures("one_torch_thread")  # fixture in tests/conftest.py


class Killed(Exception):
    pass


class KillAt:
    """A callback that stops the run (as a kill would) at its first log at or after ``step``."""

    def __init__(self, step: int) -> None:
        self.step = step

    def on_log(self, record) -> None:
        if record["step"] >= self.step:
            raise Killed(record["step"])


def _weights(policy) -> torch.Tensor:
    return torch.cat([p.detach().flatten() for p in policy.parameters()])


def _run(policy_type: str, cfg: TrainConfig, **kw):
    policy, batches, _ = make_policy(policy_type, synthetic_pusht(), batch_size=16, seed=0, unet=TINY)
    return train(policy, batches, cfg, **kw)


@pytest.mark.parametrize("kill_at", [4, 8])
def test_resumed_run_equals_the_uninterrupted_one(tmp_path, monkeypatch, kill_at):
    monkeypatch.setattr(train_state, "STATE_EVERY_S", 0.0)  # write the state at every log point
    cfg = TrainConfig(max_steps=12, warmup_steps=2, lr=1e-3, seed=0, log_every=2, progress=False)
    whole = _run("diffusion", cfg)
    state = tmp_path / "state.pt"
    with pytest.raises(Killed):
        _run("diffusion", cfg, state_file=state, callbacks=[KillAt(kill_at)])
    assert state.is_file()
    resumed = _run("diffusion", cfg, state_file=state)
    assert torch.equal(_weights(resumed.raw_policy), _weights(whole.raw_policy))
    assert torch.equal(_weights(resumed.policy), _weights(whole.policy))  # the EMA copy too
    assert [h["loss"] for h in resumed.history] == [h["loss"] for h in whole.history]
    assert resumed.summary["steps"] == 12 and resumed.summary["samples"] == whole.summary["samples"]


def test_a_state_of_another_config_or_a_time_budget_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(train_state, "STATE_EVERY_S", 0.0)
    state = tmp_path / "state.pt"
    cfg = TrainConfig(max_steps=4, warmup_steps=1, lr=1e-3, seed=0, log_every=2, progress=False)
    _run("diffusion", cfg, state_file=state)
    other = TrainConfig(max_steps=4, warmup_steps=1, lr=2e-3, seed=0, log_every=2, progress=False)
    with pytest.raises(ValueError, match=r"another training config \(differs in \['lr'\]\)"):
        _run("diffusion", other, state_file=state)
    with pytest.raises(ValueError, match="needs a step budget only"):
        _run("diffusion", TrainConfig(minutes=0.1, progress=False), state_file=tmp_path / "t.pt")
    state.write_bytes(b"not a state")
    with pytest.raises(ValueError, match="cannot read the resume state"):
        _run("diffusion", cfg, state_file=state)
