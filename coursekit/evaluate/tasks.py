"""A policy on a task: the :class:`~coursekit.evaluate.closed_loop.TaskAdapter` of a task record.

Every task is evaluated through ONE adapter class, :class:`RecordAdapter`, which reads the task's
facts from its record (``coursekit.tasks``): the env and its episode length, the state recorded per
step, the task's own figures and how an episode is scored. The policy's features (``config.features``)
turn raw observations into its inputs, so any policy type runs on any task whose observations its
features read. :func:`task_of` says which task a checkpoint was trained for.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from coursekit.tasks.record import Task
from coursekit.tasks.registry import TASKS, get_task, task_in_meta


def _world(features: str) -> str | None:
    """The feature table's world of a feature set ('pusht', 'aloha'; None: fits every task)."""
    from coursekit.data.features import get_features

    return get_features(features).task


class RecordAdapter:
    """One task for :func:`coursekit.evaluate.closed_loop.evaluate`, built from its record for one policy.

    Args:
        task: a :class:`~coursekit.tasks.Task` or a task name (or alias).
        policy: a ChunkPolicy; its ``config.features`` must fit the task (the same world of the feature table).
    """

    def __init__(self, task: Task | str, policy: Any) -> None:
        self.record = task if isinstance(task, Task) else get_task(task)
        self.task = self.record.name
        self.max_steps = self.record.max_steps
        self.record_always = self.record.metrics_fn is not None or self.record.scores_fn is not None
        c = policy.config
        self.features = c.features
        world, own = _world(self.features), _world(self.record.features)
        if world is not None and world != own:
            raise ValueError(f"policy features {self.features!r} are for the {world!r} world, not {self.task!r} "
                             f"(whose features are {own!r}); evaluate it on its own task")
        self.image_size = tuple(c.vision.input_size) if getattr(c, "obs_type", "low_dim") == "image" else None
        if self.image_size is not None and self.record.image_env_kwargs is None:
            raise ValueError(f"policy features {self.features!r} read camera images, but task {self.task!r} has none")

    def make_env(self, max_steps: int) -> Any:
        """One env of the task with a ``max_steps`` step limit (pixels + agent_pos for an image policy)."""
        pixels = {} if self.image_size is None else self.record.image_env_kwargs(self.image_size)
        return self.record.make_env(max_episode_steps=max_steps, **pixels)

    def obs_fn(self, observations: list[Any]) -> Any:
        """B raw env observations -> (B, Do) features, or {"image": (B, 3, H, W), "agent_pos": (B, Do)}.

        An image env's low-dim part is its "agent_pos" (PushT's pusher) or else the features of its
        other observations (the arm pair's "qpos" for 'aloha_image').
        """
        from coursekit.data.features import env_obs_features

        if self.image_size is None:
            return env_obs_features(self.features, observations)  # (B, Do)
        from coursekit.data.frames import frames_chw

        pixels = np.stack([o["pixels"] for o in observations])  # (B, H, W, 3) uint8
        if "agent_pos" in observations[0]:
            low = np.stack([o["agent_pos"] for o in observations]).astype(np.float32)  # (B, Do)
        else:
            low = env_obs_features(self.features, [{k: v for k, v in o.items() if k != "pixels"} for o in observations])
        return {"image": frames_chw(pixels, self.image_size, "the environment's camera frames"),  # (B, 3, H, W)
                "agent_pos": low}

    def state_fn(self, env: Any) -> np.ndarray:
        """The (S,) state recorded per step: the record's, or ``env.unwrapped.get_state()``."""
        if self.record.state_fn is not None:
            return self.record.state_fn(env)
        return np.asarray(env.unwrapped.get_state(), dtype=np.float64)

    def metrics(self, result: Any) -> dict[str, Any]:
        """The task's own figures for ``result.info`` (none for a task whose record names none)."""
        return {} if self.record.metrics_fn is None else self.record.metrics_fn(result)

    def replay_states(self, result: Any) -> np.ndarray:
        """(N, T + 1, S') the columns of the recorded states that the task's replay draws."""
        if self.record.replay is None:
            raise ValueError(f"task {self.task!r} has no replay drawing")
        start, stop = self.record.replay.columns
        return result.states[..., start:stop]

    def episode_scores(self, result: Any) -> tuple[np.ndarray, np.ndarray]:
        """(score (N,), success (N,)) of each episode, as the task's protocol reports them."""
        if self.record.scores_fn is not None:
            return self.record.scores_fn(result)
        return result.max_reward, result.success


def make_adapter(task: Task | str, policy: Any) -> RecordAdapter:
    """The adapter of ``task`` (a record or a name) for ``policy``."""
    return RecordAdapter(task, policy)


def task_of(policy: Any, dataset_meta: dict[str, Any] | None) -> Task:
    """The task a policy was trained for: the one its data's meta names, else the only task its features fit."""
    named = task_in_meta(dataset_meta)
    if named is not None:
        return named
    world = _world(policy.config.features)
    fits = [t.name for t in TASKS.values() if world is not None and _world(t.features) == world]
    if len(fits) != 1:
        raise ValueError(f"the policy's dataset meta names no known task (its 'task' or 'env_id') and its features "
                         f"{policy.config.features!r} fit {fits or 'no task in particular'}; expected a meta naming "
                         f"one of {list(TASKS)}")
    return TASKS[fits[0]]
