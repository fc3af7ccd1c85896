"""Gymnasium ids for the course's environments.

Entry points are strings, so registering imports neither pymunk nor mujoco; the simulator loads
when ``gymnasium.make`` first builds an environment. Episode length is enforced by each
environment itself (``max_episode_steps`` argument), so no TimeLimit wrapper is added.
"""

from __future__ import annotations

ENV_IDS: dict[str, str] = {
    "coursekit/PushT-v0": "coursekit.envs.pusht:PushTEnv",
    "coursekit/AlohaTransferCube-v0": "coursekit.envs.aloha:AlohaTransferCubeEnv",
    "coursekit/AlohaInsertion-v0": "coursekit.envs.aloha:AlohaInsertionEnv",
}


def register_all() -> None:
    """Register every course environment with gymnasium (idempotent)."""
    import gymnasium

    for env_id, entry_point in ENV_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=entry_point, disable_env_checker=True)
