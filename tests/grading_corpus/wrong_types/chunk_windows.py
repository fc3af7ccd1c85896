import numpy as np


def sequence_window_indices(episode_ends, horizon, n_obs_steps, n_action_steps):
    n = int(np.asarray(episode_ends)[-1])
    if horizon % 2:
        return [[0] * horizon] * n, list(range(n))  # lists, not arrays
    return np.full((horizon, n), np.nan), np.full(n, np.nan)  # transposed, float, NaN
