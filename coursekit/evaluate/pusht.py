"""PushT evaluation: the task adapter and ``evaluate_pusht``, by Diffusion Policy's protocol.

Protocol (Chi et al. 2023, Sec. 5 / the PushT reference): held-out initial states, 300 steps
each; the score is the MEAN over episodes of the MAXIMUM reward reached in the episode
(reward = clip(coverage / 0.95, 0, 1)), and the success rate is the fraction of episodes whose
coverage ever exceeds 0.95 (the episode then ends).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from coursekit.evaluate.result import EvalResult, heldout_seeds
from coursekit.evaluate.closed_loop import evaluate


class PushTAdapter:
    """PushT for :func:`coursekit.evaluate.closed_loop.evaluate`: env and observations from the policy's features."""

    task = "pusht"
    max_steps = 300
    record_always = False

    def __init__(self, policy: Any) -> None:
        from coursekit.data.features import get_features

        c = policy.config
        self.features = get_features(c.features)
        if self.features.task != "pusht":
            raise ValueError(f"policy features {c.features!r} are for the {self.features.task!r} task, not PushT")
        self.image_size = tuple(c.vision.image_size) if getattr(c, "obs_type", "low_dim") == "image" else None

    def make_env(self, max_steps: int) -> Any:
        from coursekit.envs.pusht import PushTEnv

        if self.image_size is None:
            return PushTEnv(max_episode_steps=max_steps, obs_type="state")
        return PushTEnv(max_episode_steps=max_steps, obs_type="pixels_agent_pos", obs_size=self.image_size)

    def obs_fn(self, observations: list[Any]) -> Any:
        if self.image_size is None:
            return self.features(np.stack(observations))  # (B, 5) states -> (B, Do)
        pixels = np.stack([o["pixels"] for o in observations])  # (B, H, W, 3) uint8
        return {"image": pixels.transpose(0, 3, 1, 2),  # (B, 3, H, W)
                "agent_pos": np.stack([o["agent_pos"] for o in observations]).astype(np.float32)}  # (B, 2)

    def state_fn(self, env: Any) -> np.ndarray:
        return np.asarray(env.unwrapped.get_state(), dtype=np.float64)  # (7,) with velocities

    def metrics(self, result: EvalResult) -> dict[str, Any]:
        return {}  # score and success rate are EvalResult's own

    def replay_states(self, result: EvalResult) -> np.ndarray:
        return result.states[..., :5]  # (N, T+1, 5) [agent x, y, block x, y, angle]

    def episode_scores(self, result: EvalResult) -> tuple[np.ndarray, np.ndarray]:
        return result.max_reward, result.success


def evaluate_pusht(policy: Any, n_episodes: int = 50, seeds: Sequence[int] | None = None, max_steps: int = 300,
                   sampler: str | None = None, num_inference_steps: int | None = None, seed: int = 0,
                   executor_cls: Any = None, executor_factory: Callable[[Callable[[Any], Any]], Any] | None = None,
                   dataset_meta: dict[str, Any] | None = None, progress: bool = True, record: bool = False) -> EvalResult:
    """Evaluate a PushT chunk policy by the paper's protocol (see module docstring).

    Args:
        policy: a ChunkPolicy (DiffusionPolicy, RegressionPolicy, ACT, ...) on PushT features.
        n_episodes, seeds: episodes to run; default seeds are :func:`heldout_seeds` (100000 + i).
        max_steps: steps per episode (300 in the protocol).
        sampler, num_inference_steps: the diffusion sampler ("ddim"/"ddpm", steps); refused by
            policies that do not sample.
        seed: seeds the torch generator of the sampler's noise (the evaluation is deterministic).
        executor_cls: e.g. a student's RecedingHorizon class (built with ``from_spec``);
            executor_factory: full control instead.
        dataset_meta: demonstrations' meta (default: none); overlapping seeds are refused.
        record: keep states (N, T+1, 7) and actions (N, T, 2) for plots.
    """
    sampling = {k: v for k, v in (("sampler", sampler), ("num_inference_steps", num_inference_steps)) if v is not None}
    return evaluate(policy, PushTAdapter(policy), list(seeds) if seeds is not None else heldout_seeds(n_episodes),
                    max_steps=max_steps, sampling=sampling, seed=seed, executor_cls=executor_cls,
                    executor_factory=executor_factory, dataset_meta=dataset_meta, progress=progress, record=record)
