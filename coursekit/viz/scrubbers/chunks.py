"""Chapter 5's scrubber: replay a PushT rollout and see which chunk was in use at every step.

Diffusion Policy (Chi et al. 2023, Sec. 3.1) predicts Tp = horizon actions from the last
To = n_obs_steps observations and executes Ta = n_action_steps of them before predicting again.
:func:`record_chunk_rollouts` runs one held-out episode per Ta and keeps every chunk with the
step it was made at; :func:`chunk_replay` scrubs through them: pick Ta, move the step slider,
and the figure shows the scene at that step, the To observed pusher positions, the chunk in use
(its Ta executed actions bold, the rest of the Tp it predicted faded) and the path so far.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from coursekit.viz.scrubbers.figure import FigureScrubber

__all__ = ["ChunkRollout", "chunk_replay", "record_chunk_rollouts"]


@dataclass
class ChunkRollout:
    """One recorded episode and its chunks.

    states: (T + 1, S) simulator states (first 5: [ax, ay, bx, by, angle]); actions: (T, 2)
    executed; chunks: (C, Tp, 2) every predicted chunk; made_at: (C,) the step each was made at.
    """

    n_obs_steps: int
    n_action_steps: int
    states: np.ndarray
    actions: np.ndarray
    chunks: np.ndarray
    made_at: np.ndarray
    max_reward: float

    def chunk_at(self, t: int) -> int:
        """Index of the chunk in use at step t (the latest made at or before t)."""
        return int(np.searchsorted(self.made_at, t, side="right") - 1)


class _CountingExecutor:
    """Wraps an executor: counts control steps and records each chunk with the step it was made at."""

    def __init__(self, executor_cls: Any, predict_chunk: Any, n_obs_steps: int, n_action_steps: int):
        self.t, self.made = 0, []

        def predict(history: Any) -> Any:
            chunk = predict_chunk(history)
            data = chunk.detach().cpu().numpy() if hasattr(chunk, "detach") else np.asarray(chunk)
            self.made.append((self.t, data[0].copy()))  # (Tp, Da) of the first environment
            return chunk

        self.inner = executor_cls(predict, n_obs_steps, n_action_steps)

    def reset(self, obs: Any) -> Any:
        self.t, self.made = 0, []
        return self.inner.reset(obs)

    def act(self, obs: Any) -> Any:
        action = self.inner.act(obs)
        self.t += 1
        return action


def record_chunk_rollouts(policy: Any, seed: int, n_action_steps: Sequence[int], max_steps: int = 100,
                          executor_cls: Any = None, **eval_kwargs: Any) -> dict[int, ChunkRollout]:
    """One held-out episode (reset ``seed``) per Ta in ``n_action_steps``, chunks recorded.

    ``executor_cls``: a receding-horizon class called as ``cls(predict_chunk, To, Ta)`` (default:
    the library's ``RecedingHorizon``; pass the student's). Extra keyword arguments go to
    ``evaluate_pusht`` (e.g. ``dataset_meta``).
    """
    from coursekit.evaluate import evaluate_pusht
    from coursekit.execution import RecedingHorizon

    cls = executor_cls or RecedingHorizon
    to, tp = policy.config.n_obs_steps, policy.config.horizon
    out = {}
    for ta in n_action_steps:
        if not 1 <= int(ta) <= tp - to + 1:
            raise ValueError(f"Ta = {ta} must be between 1 and Tp - To + 1 = {tp - to + 1}")
        made: list = []

        def factory(pc: Any, ta: int = int(ta)) -> _CountingExecutor:
            ex = _CountingExecutor(cls, pc, to, ta)
            made.append(ex)
            return ex

        r = evaluate_pusht(policy, seeds=[int(seed)], max_steps=max_steps, executor_factory=factory, record=True,
                           progress=False, **eval_kwargs)
        n = int(r.length[0])
        steps, chunks = zip(*made[-1].made)
        out[int(ta)] = ChunkRollout(to, int(ta), r.states[0, : n + 1], r.actions[0, :n], np.stack(chunks),
                                    np.asarray(steps), float(r.max_reward[0]))
    return out


def draw_chunk_step(ax: Any, run: ChunkRollout, t: int) -> None:
    """The scene at step t with the chunk in use, its executed part and the observed history."""
    from coursekit.viz.pusht_plots import draw_scene

    t = int(np.clip(t, 0, len(run.actions) - 1))
    c = run.chunk_at(t)
    chunk, t0 = run.chunks[c], int(run.made_at[c])
    to, ta = run.n_obs_steps, run.n_action_steps
    draw_scene(ax, run.states[t, :5], title=f"step {t}: chunk {c} made at step {t0} (Ta = {ta})")
    path = run.states[: t + 1, :2]
    ax.plot(path[:, 0], path[:, 1], color="tab:blue", lw=1, alpha=0.6, label="pusher path")
    # chunk row j is meant for step t0 - (To - 1) + j: rows before To - 1 lie in the past
    ax.plot(chunk[:, 0], chunk[:, 1], "o--", color="tab:orange", ms=3, lw=1, alpha=0.45,
            label=f"all Tp = {len(chunk)} predicted")
    run_part = chunk[to - 1: to - 1 + ta]
    ax.plot(run_part[:, 0], run_part[:, 1], "o-", color="tab:red", ms=4, lw=2, label=f"Ta = {ta} executed")
    now = min(to - 1 + (t - t0), len(chunk) - 1)
    ax.plot(*chunk[now], "x", color="k", ms=10, mew=2, label="target now")
    obs = run.states[max(0, t0 - to + 1): t0 + 1, :2]
    ax.plot(obs[:, 0], obs[:, 1], "s", color="tab:green", ms=6, label=f"To = {to} observed")
    ax.legend(fontsize=8, loc="lower left")


def chunk_replay(runs: dict[int, ChunkRollout]) -> FigureScrubber:
    """Chapter 5: pick Ta, scrub the step; the figure redraws in place (needs a live kernel)."""
    import ipywidgets as widgets

    if not runs:
        raise ValueError("runs is empty: record some with record_chunk_rollouts")
    tas = sorted(runs)
    longest = max(len(r.actions) for r in runs.values())

    def draw(fig: Figure, ta: int, step: int) -> None:
        run = runs[ta]
        ax_scene, ax_time = fig.subplots(1, 2, width_ratios=[1.0, 0.6])
        draw_chunk_step(ax_scene, run, step)
        n = len(run.actions)
        ax_time.vlines(run.made_at, 0, 1, color="tab:orange", lw=1, label="a chunk is predicted")
        ax_time.axvline(min(step, n - 1), color="k", lw=2, label="this step")
        ax_time.set(xlim=(-1, longest), ylim=(0, 1), yticks=[], xlabel="control step")
        ax_time.set_title(f"Ta = {ta}: {len(run.made_at)} network calls in {n} steps\nmax reward {run.max_reward:.2f}",
                          fontsize=9)
        ax_time.legend(fontsize=8, loc="upper right")

    controls = {
        "ta": widgets.Dropdown(options=tas, value=tas[-1], description="Ta"),
        "step": widgets.IntSlider(value=0, min=0, max=longest - 1, description="step", continuous_update=True),
    }
    return FigureScrubber(draw, controls, figsize=(9.0, 4.2))
