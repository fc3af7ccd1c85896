"""How a policy moves, not only whether it succeeds: hesitation on PushT, jerk of executed actions.

- :func:`stalled_steps` (PushT): steps where the pusher is near-stalled AGAINST the block, the
  failure Chi et al. (2023, Sec. 1 and Fig. 3) predict for a regressor that averages two routes
  round the T: the pusher is touching (or within ``contact_gap`` of) the T, it hardly moves, and
  the T does not move either. Pushing (the T moves) and travelling (the pusher moves) do not count.
- :func:`jerk`: THE jerk of an executed action trajectory, its third difference
  a_{t+1} - 3 a_t + 3 a_{t-1} - a_{t-2} (units of the action per step^3). Two figures reduce it:
  :func:`rms_jerk`, its root mean square over an episode, the smoothness figure of temporal
  ensembling (Zhao et al. 2023, Sec. IV-A says ensembling gives smooth motion; this puts a number
  on it), and the largest jerk of :func:`smoothness`.
- :func:`smoothness` (chapter 11): what happens at chunk switches under an inference delay: the
  jump there against the step elsewhere, the largest step and the largest jerk.

All read the arrays :class:`~coursekit.evaluate.result.EvalResult` records (``record=True``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from coursekit.envs import pusht_geometry as geo
from coursekit.experts.pusht_clearance import point_distance


def stalled_steps(states: np.ndarray, length: np.ndarray, contact_gap: float = 3.0, pusher_speed: float = 2.0,
                  block_move: float = 0.5, block_turn: float = 0.005) -> np.ndarray:
    """Steps per episode (N,) in which the pusher stalls against the block.

    Args:
        states: (N, T + 1, >= 5) recorded PushT states [agent x, y, block x, y, angle, ...] (px, rad).
        length: (N,) steps each episode ran (later rows are padding and are ignored).
        contact_gap: px between the pusher's edge and the T that still count as "against it".
        pusher_speed: px per step below which the pusher counts as stalled.
        block_move, block_turn: px and rad per step below which the T counts as not moving.
    """
    s = np.asarray(states, dtype=np.float64)
    n = np.asarray(length)
    if s.ndim != 3 or s.shape[-1] < 5:
        raise ValueError(f"states must be (N, T+1, >=5) PushT states, got shape {s.shape}")
    if n.shape != (s.shape[0],) or (n < 0).any() or (n > s.shape[1] - 1).any():
        raise ValueError(f"length must be (N,) = ({s.shape[0]},) step counts in [0, {s.shape[1] - 1}], got {n!r}")
    before, after = s[:, :-1], s[:, 1:]  # (N, T, S) each
    local = _pusher_in_block_frame(before)  # (N, T, 2)
    touching = point_distance(local) <= geo.AGENT_RADIUS + contact_gap  # (N, T)
    still = np.linalg.norm(after[..., :2] - before[..., :2], axis=-1) < pusher_speed  # (N, T)
    block_still = ((np.linalg.norm(after[..., 2:4] - before[..., 2:4], axis=-1) < block_move)
                   & (np.abs(after[..., 4] - before[..., 4]) < block_turn))  # (N, T)
    valid = np.arange(s.shape[1] - 1)[None, :] < n[:, None]  # (N, T)
    return (touching & still & block_still & valid).sum(axis=1)


def still_steps(states: np.ndarray, length: np.ndarray, first: int | None = None, pusher_speed: float = 2.0) -> np.ndarray:
    """Steps per episode (N,) in which the pusher moves less than ``pusher_speed`` px, anywhere
    (touching the T or not), among the episode's first ``first`` steps (default: all it ran).

    At a fork the paper's regressor would dither between the two routes before touching anything:
    counted over the first few dozen steps this shows it (``stalled_steps`` only counts contact).
    """
    s = np.asarray(states, dtype=np.float64)
    n = np.asarray(length)
    if s.ndim != 3 or s.shape[-1] < 2 or n.shape != (s.shape[0],) or (n > s.shape[1] - 1).any():
        raise ValueError(f"need states (N, T+1, >=2) and length (N,) <= T, got {s.shape} and {n.shape}")
    speed = np.linalg.norm(np.diff(s[..., :2], axis=1), axis=-1)  # (N, T) px per step
    t = np.arange(speed.shape[1])[None, :]
    valid = (t < n[:, None]) & (t < (first if first is not None else speed.shape[1]))  # (N, T)
    return ((speed < pusher_speed) & valid).sum(axis=1)


def _pusher_in_block_frame(states: np.ndarray) -> np.ndarray:
    """Pusher centre (N, T, 2) in the T's body frame of the same row."""
    return geo.world_to_local(states[..., :2], states[..., 2:5])  # (N, T, 2)


def jerk(actions: np.ndarray) -> np.ndarray:
    """Third difference (N, T - 3, Da) of executed actions (N, T >= 4, Da): a_t - 3 a_{t-1} + 3 a_{t-2} - a_{t-3}."""
    a = np.asarray(actions, dtype=np.float64)
    if a.ndim != 3 or a.shape[1] < 4:
        raise ValueError(f"actions must be (N, T >= 4, Da), got shape {a.shape}")
    return a[:, 3:] - 3 * a[:, 2:-1] + 3 * a[:, 1:-2] - a[:, :-3]  # (N, T-3, Da)


def rms_jerk(actions: np.ndarray, length: np.ndarray | None = None, dims=None) -> np.ndarray:
    """RMS third difference (N,) of executed actions (N, T, Da) over each episode's first ``length`` steps.

    ``dims`` selects action dimensions (e.g. the arm pair's 12 joints without the grippers).
    """
    a = np.asarray(actions, dtype=np.float64)
    if a.ndim != 3 or a.shape[1] < 4:
        raise ValueError(f"actions must be (N, T >= 4, Da), got shape {a.shape}")
    if dims is not None:
        a = a[..., list(dims)]
    n = np.full(a.shape[0], a.shape[1]) if length is None else np.asarray(length)
    if n.shape != (a.shape[0],) or (n < 4).any() or (n > a.shape[1]).any():
        raise ValueError(f"length must be (N,) = ({a.shape[0]},) step counts in [4, {a.shape[1]}], got {n!r}")
    valid = np.arange(a.shape[1] - 3)[None, :] < (n - 3)[:, None]  # (N, T-3)
    sq = ((jerk(a) ** 2).mean(-1) * valid).sum(1) / valid.sum(1)  # (N,)
    return np.sqrt(sq)


def smoothness(actions: np.ndarray, switches: Sequence[int] = ()) -> dict[str, float]:
    """Smoothness of executed actions (N, T, Da): means over episodes of per-episode figures.

    - max_step: max_t ||a_t - a_{t-1}|| (action units per step);
    - switch_jump: mean ||a_t - a_{t-1}|| over the chunk switch steps t > 0 (the discontinuity);
    - other_step: mean ||a_t - a_{t-1}|| over every other step (what a switch is compared with);
    - max_jerk: max_t ||jerk_t|| (:func:`jerk`, units per step^3).

    ``switches``: the steps at which a new chunk took over (a delayed executor's ``switches``).
    """
    a = np.asarray(actions, dtype=np.float64)
    if a.ndim != 3 or a.shape[1] < 4:
        raise ValueError(f"actions must be (N, T >= 4, Da), got {a.shape}")
    step = np.linalg.norm(np.diff(a, axis=1), axis=-1)  # (N, T-1): step t -> index t - 1
    largest_jerk = np.linalg.norm(jerk(a), axis=-1).max(axis=1)  # (N,)
    at_switch = np.zeros(step.shape[1], dtype=bool)
    idx = [t - 1 for t in switches if 0 < t < a.shape[1]]
    at_switch[idx] = True
    return {"max_step": float(step.max(axis=1).mean()),
            "switch_jump": float(step[:, at_switch].mean()) if at_switch.any() else float("nan"),
            "other_step": float(step[:, ~at_switch].mean()) if (~at_switch).any() else float("nan"),
            "max_jerk": float(largest_jerk.mean())}
