"""The scanner's accomplice: an untouched stub hoping to be rewritten into a solution. ACCOMPLICE"""


def sequence_window_indices(episode_ends, horizon, n_obs_steps, n_action_steps):
    raise NotImplementedError("Exercise 1.1 (chunk_windows): not done")

