"""PushT (Chi et al. 2023, Sec. 5): push the T onto its goal pose with a round pusher.

Evaluation protocol (Diffusion Policy's): held-out initial states, 300 steps each; the score is
the MEAN over episodes of the MAXIMUM reward reached (reward = clip(coverage / 0.95, 0, 1)) and
the success rate the fraction of episodes whose coverage ever exceeds 0.95 (the episode then
ends). Both are ``EvalResult``'s own figures, so the record adds no metrics of its own.
"""

from __future__ import annotations

from typing import Any

from coursekit.tasks.record import ReplayDrawing, Task


def _pixels(image_hw: tuple[int, int]) -> dict[str, Any]:
    """Env kwargs of an image policy: (H, W, 3) camera pixels and the pusher position."""
    return {"obs_type": "pixels_agent_pos", "obs_size": tuple(image_hw)}


PUSHT = Task(
    name="pusht",
    gym_id="coursekit/PushT-v0",
    env="coursekit.envs.pusht:PushTEnv",
    control_hz=10.0,
    max_steps=300,
    features="pusht_state",
    expert="coursekit.experts.pusht_planner:collect_dataset",
    expert_options=("action_noise", "style"),
    demo_episodes=200,
    image_env_kwargs=_pixels,
    replay=ReplayDrawing(viewer="pusht", columns=(0, 5), panel_hw=(256, 256)),
)
"""PushT: 10 Hz pusher targets, 300-step episodes; the state recorded per step is ``PushTEnv.get_state()`` (7,)."""
