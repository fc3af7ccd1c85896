def sequence_window_indices(episode_ends, horizon, n_obs_steps, n_action_steps):
    line = "y" * 100_000
    while True:
        print(line)
