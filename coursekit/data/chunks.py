"""Training windows over demonstrations: what one training sample of a chunk policy sees.

Two conventions, both as index tables into the flat arrays of an :class:`EpisodeDataset`, so a
whole batch is one numpy gather (fast on a CPU, no per-sample Python):

Diffusion Policy (Chi et al. 2023, Sec. 3.1 and the reference code's sequence sampler)::

    window of Tp = horizon steps, e.g. To = 2, Ta = 8, Tp = 16
    time      t-1  t   t+1 ...                      t+14
    obs       [o   o]                                        <- first To steps
    action    [a   a   a   a   a   a   a   a   a   ... a]    <- all Tp steps
    executed       [a   a   a   a   a   a   a   a]           <- pred[To-1 : To-1+Ta]

  Windows may start up to To - 1 steps before an episode and end up to Ta - 1 steps after it;
  the missing steps repeat the first / last step of the episode (edge padding).

ACT (Zhao et al. 2023, Sec. IV and its data loader)::

    qpos[t], actions[t : t+k] with an is_pad mask; steps past the episode end are zero and
    marked is_pad = True (the L1 loss ignores them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coursekit.execution.spec import check_horizons


def _check_ends(episode_ends: np.ndarray) -> np.ndarray:
    ends = np.asarray(episode_ends, dtype=np.int64)
    if ends.ndim != 1 or len(ends) == 0:
        raise ValueError(f"episode_ends must be a non-empty 1-d array, got shape {ends.shape}")
    if ends[0] <= 0 or np.any(np.diff(ends) <= 0):
        raise ValueError(f"episode_ends must be strictly increasing and positive, got {ends[:10]}")
    return ends


def sequence_window_indices(episode_ends: np.ndarray, horizon: int, n_obs_steps: int,
                            n_action_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Index table of every Diffusion Policy training window (exercise "chunk_windows", Ch. 1).

    Episode ``e`` owns the flat rows ``[s_e, t_e)`` with ``s_e = episode_ends[e-1]`` (0 for the
    first episode) and ``t_e = episode_ends[e]``. With To = n_obs_steps, Tp = horizon and
    Ta = n_action_steps, its windows start at every ``w`` with

        s_e - (To - 1)  <=  w  <=  max(t_e - Tp + (Ta - 1),  s_e - (To - 1))

    (so an episode shorter than a window still yields exactly one), and window ``w`` holds

        indices[w, j] = clip(w + j, s_e, t_e - 1)      for j = 0 .. Tp - 1,

    i.e. steps before the episode repeat its first step and steps after it repeat its last step
    (edge padding). The padding lets the first executed action, pred[To - 1], be the episode's
    first action, and the last chunk still run Ta steps. Windows never cross episodes.

    Args:
        episode_ends: (E,) strictly increasing positive ints, one past each episode's last row.
        horizon: Tp, steps per window.
        n_obs_steps: To, observation steps at the start of each window.
        n_action_steps: Ta, actions executed per chunk; To - 1 + Ta must be <= Tp.

    Returns:
        indices: (W, Tp) int64 rows into the per-step arrays, episodes in order, w increasing.
        episode: (W,) int64 episode of each window.
    """
    ends = _check_ends(episode_ends)
    check_horizons(n_obs_steps, horizon, n_action_steps)
    # BEGIN SOLUTION
    pad_before, pad_after = n_obs_steps - 1, n_action_steps - 1
    starts = np.concatenate([[0], ends[:-1]])
    rows, eps = [], []
    offsets = np.arange(horizon)
    for e, (s, t) in enumerate(zip(starts, ends)):
        # first window starts pad_before steps early, last one ends pad_after steps late
        first, last = s - pad_before, t - horizon + pad_after
        window_starts = np.arange(first, max(last, first) + 1)
        idx = np.clip(window_starts[:, None] + offsets[None, :], s, t - 1)  # (w_e, Tp)
        rows.append(idx)
        eps.append(np.full(len(idx), e))
    indices = np.concatenate(rows).astype(np.int64)  # (W, Tp)
    episode = np.concatenate(eps).astype(np.int64)  # (W,)
    # END SOLUTION
    return indices, episode


@dataclass(frozen=True)
class SequenceWindows:
    """Diffusion Policy windows: index table of shape (n_windows, horizon) into the flat arrays.

    Attributes:
        indices: (W, Tp) int64 rows into the per-step arrays (edge padding = clamped indices).
        episode: (W,) int64 episode of each window.
        n_obs_steps: To, observation steps at the start of each window.
        horizon: Tp, steps per window (= actions per chunk).
    """

    indices: np.ndarray
    episode: np.ndarray
    n_obs_steps: int
    horizon: int

    @classmethod
    def build(cls, episode_ends: np.ndarray, horizon: int = 16, n_obs_steps: int = 2,
              n_action_steps: int = 8) -> SequenceWindows:
        """Every window of Tp steps, padded by To - 1 before and Ta - 1 after each episode."""
        indices, episode = sequence_window_indices(episode_ends, horizon, n_obs_steps, n_action_steps)
        return cls(indices, episode, int(n_obs_steps), int(horizon))

    def __len__(self) -> int:
        return len(self.indices)

    def gather(self, obs: np.ndarray, action: np.ndarray, which: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Batch ``which`` (B,) of windows: obs (B, To, ...) and action (B, Tp, ...)."""
        idx = self.indices[which]  # (B, Tp)
        return obs[idx[:, : self.n_obs_steps]], action[idx]


@dataclass(frozen=True)
class ActionChunks:
    """ACT windows: one per step t, k future actions zero-padded past the episode end.

    Attributes:
        start: (W,) int64 row of the observation (time t) of each window.
        indices: (W, k) int64 action rows, clamped to the episode (values masked by is_pad).
        is_pad: (W, k) bool, True where t + j is past the episode end.
        chunk_size: k.
    """

    start: np.ndarray
    indices: np.ndarray
    is_pad: np.ndarray
    chunk_size: int

    @classmethod
    def build(cls, episode_ends: np.ndarray, chunk_size: int = 100) -> ActionChunks:
        ends = _check_ends(episode_ends)
        if not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1:
            raise ValueError(f"chunk_size must be a positive integer, got {chunk_size!r}")
        starts = np.concatenate([[0], ends[:-1]])
        t = np.arange(int(ends[-1]))
        episode_end = np.repeat(ends, ends - starts)  # (N,) end of the episode each row is in
        raw = t[:, None] + np.arange(chunk_size)[None, :]  # (N, k)
        is_pad = raw >= episode_end[:, None]
        indices = np.minimum(raw, episode_end[:, None] - 1)
        return cls(t.astype(np.int64), indices.astype(np.int64), is_pad, int(chunk_size))

    def __len__(self) -> int:
        return len(self.start)

    def gather(self, obs: np.ndarray, action: np.ndarray, which: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Batch ``which`` (B,): obs (B, ...) at time t, actions (B, k, Da) zeroed where padded, is_pad (B, k)."""
        pad = self.is_pad[which]  # (B, k)
        act = action[self.indices[which]].copy()  # (B, k, Da)
        act[pad] = 0.0
        return obs[self.start[which]], act, pad
