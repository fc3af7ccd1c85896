"""Closed-loop evaluation: many seeded episodes in lock-step, one network call per chunk for all.

Protocol (Diffusion Policy, Chi et al. 2023, Sec. 5 / the PushT reference): 50 held-out initial
states, 300 steps each; the score is the MEAN over episodes of the MAXIMUM reward reached in the
episode (reward = clip(coverage / 0.95, 0, 1)), and the success rate is the fraction of episodes
whose coverage ever exceeds 0.95 (the episode then ends).

Held-out seeds: episode i of an evaluation uses reset seed ``EVAL_SEED_START + i`` = 100000 + i.
Demonstrations are collected from small seeds (``coursekit collect pusht --seed S`` uses seeds
S .. S + n - 1, S = 0 by default), so the two sets are disjoint; ``evaluate_pusht`` checks it
against the dataset metadata stored in the checkpoint and refuses an overlap.

The generic part, :func:`rollout`, is policy- and task-agnostic (ACT on the arm pair uses it
with its own ``make_env``/``obs_fn``): B environments step together, an executor (receding
horizon, temporal ensembling, or a student's class) turns chunks into actions, and finished
episodes are frozen while the others go on. Everything is seeded, so a run is reproducible.
"""

from __future__ import annotations

import inspect
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from tqdm.auto import tqdm

EVAL_SEED_START = 100_000
"""First held-out evaluation seed (episode i uses EVAL_SEED_START + i)."""


def heldout_seeds(n_episodes: int = 50, start: int = EVAL_SEED_START) -> list[int]:
    """The reset seeds of an n-episode evaluation: start, start + 1, ..."""
    if not isinstance(n_episodes, int) or n_episodes < 1:
        raise ValueError(f"n_episodes must be a positive int, got {n_episodes!r}")
    return list(range(start, start + n_episodes))


@dataclass
class EvalResult:
    """Per-episode outcomes of an evaluation.

    Attributes:
        seeds: (N,) reset seeds.
        max_reward: (N,) maximum reward reached in each episode.
        success: (N,) whether each episode succeeded (info["is_success"] at some step).
        length: (N,) steps each episode ran (until success or the step limit).
        seconds: wall-clock time of the whole evaluation.
        chunk_calls: calls of the chunk predictor (each for all N environments at once).
        chunk_seconds: time spent inside the chunk predictor.
        states: (N, T + 1, S) recorded simulator states (``record=True``), else None.
        actions: (N, T, Da) executed actions (``record=True``), else None.
        info: free-form extras (sampler, steps, checkpoint, ...).
    """

    seeds: list[int]
    max_reward: np.ndarray
    success: np.ndarray
    length: np.ndarray
    seconds: float
    chunk_calls: int
    chunk_seconds: float
    states: np.ndarray | None = None
    actions: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def score(self) -> float:
        """Mean over episodes of the max reward (the paper's PushT score)."""
        return float(np.mean(self.max_reward))

    @property
    def success_rate(self) -> float:
        return float(np.mean(self.success))

    @property
    def ms_per_chunk(self) -> float:
        """Average milliseconds per chunk-predictor call (batched over all environments)."""
        return 1000.0 * self.chunk_seconds / max(1, self.chunk_calls)

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary: score, success rate, standard error, episodes, timing."""
        n = len(self.seeds)
        return {"score": round(self.score, 4), "success_rate": round(self.success_rate, 4),
                "score_stderr": round(float(np.std(self.max_reward, ddof=1) / np.sqrt(n)) if n > 1 else 0.0, 4),
                "episodes": n, "seeds": f"{self.seeds[0]}..{self.seeds[-1]}", "seconds": round(self.seconds, 2),
                "chunk_calls": self.chunk_calls, "ms_per_chunk": round(self.ms_per_chunk, 2), **self.info}

    def __repr__(self) -> str:
        return (f"EvalResult(score={self.score:.3f}, success_rate={self.success_rate:.2f}, "
                f"episodes={len(self.seeds)}, seconds={self.seconds:.1f})")


def rollout(predict_chunk: Callable[[Any], Any], make_env: Callable[[], Any], obs_fn: Callable[[list[Any]], Any],
            seeds: Sequence[int], executor_factory: Callable[[Callable[[Any], Any]], Any], max_steps: int = 300,
            progress: bool = True, record: bool = False, state_fn: Callable[[Any], np.ndarray] | None = None,
            desc: str = "eval") -> EvalResult:
    """Run one episode per seed, all environments in lock-step, and collect the outcomes.

    Args:
        predict_chunk: (B, To, ...) observation history -> (B, Tp, Da) chunk (raw units).
        make_env: builds one gymnasium environment (called len(seeds) times).
        obs_fn: list of B raw env observations -> the policy's per-step input (B, ...) (array or dict).
        seeds: reset seed of each episode.
        executor_factory: predict_chunk -> executor with ``reset(obs)`` / ``act(obs) -> (B, Da)``.
        max_steps: step limit per episode.
        record: keep states (via ``state_fn(env)``, default ``env.unwrapped.get_state()``) and actions.
    """
    if len(seeds) == 0:
        raise ValueError("rollout needs at least one seed")
    timing = {"calls": 0, "seconds": 0.0}

    def timed(obs_history: Any) -> Any:
        t0 = time.perf_counter()
        out = predict_chunk(obs_history)
        timing["seconds"] += time.perf_counter() - t0
        timing["calls"] += 1
        return out

    state_fn = state_fn or (lambda env: np.asarray(env.unwrapped.get_state(), dtype=np.float64))
    start = time.perf_counter()
    envs = [make_env() for _ in seeds]
    n = len(envs)
    obs = [env.reset(seed=int(s))[0] for env, s in zip(envs, seeds)]
    executor = executor_factory(timed)
    executor.reset(obs_fn(obs))
    max_reward = np.zeros(n)
    success = np.zeros(n, dtype=bool)
    length = np.zeros(n, dtype=np.int64)
    done = np.zeros(n, dtype=bool)
    states = [[state_fn(e)] for e in envs] if record else None
    actions: list[list[np.ndarray]] | None = [[] for _ in envs] if record else None
    bar = tqdm(range(max_steps), desc=desc, disable=not progress, dynamic_ncols=True, leave=False)
    try:
        for _ in bar:
            act = executor.act(obs_fn(obs))
            act = act.detach().cpu().numpy() if hasattr(act, "detach") else np.asarray(act)  # (B, Da)
            for i, env in enumerate(envs):
                if done[i]:
                    continue
                obs[i], reward, terminated, truncated, info = env.step(act[i])
                max_reward[i] = max(max_reward[i], float(reward))
                success[i] |= bool(info.get("is_success", terminated))
                length[i] += 1
                done[i] = terminated or truncated
                if record:
                    states[i].append(state_fn(env))
                    actions[i].append(np.asarray(act[i], dtype=np.float64))
            bar.set_postfix(score=f"{max_reward.mean():.3f}", done=f"{int(done.sum())}/{n}")
            if done.all():
                break
    finally:
        bar.close()
        for env in envs:
            env.close()
    if record:  # pad finished episodes with their last state/action so the arrays are rectangular
        t_max = max(len(a) for a in actions)
        states = np.stack([np.stack(s + [s[-1]] * (t_max + 1 - len(s))) for s in states])  # (N, T+1, S)
        actions = np.stack([np.stack(a + [a[-1]] * (t_max - len(a))) if a else np.zeros((t_max, act.shape[-1]))
                            for a in actions])  # (N, T, Da)
    return EvalResult(seeds=[int(s) for s in seeds], max_reward=max_reward, success=success, length=length,
                      seconds=time.perf_counter() - start, chunk_calls=timing["calls"],
                      chunk_seconds=timing["seconds"], states=states, actions=actions)


def _accepted_kwargs(fn: Callable[..., Any], kwargs: dict[str, Any]) -> dict[str, Any]:
    """The subset of ``kwargs`` that ``fn`` accepts (all of them if it takes **kwargs)."""
    params = inspect.signature(fn).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return kwargs
    return {k: v for k, v in kwargs.items() if k in params}


def check_seeds_disjoint(seeds: Sequence[int], dataset_meta: dict[str, Any] | None) -> None:
    """Refuse evaluation seeds that were demonstration seeds (meta "episode_seeds", or "seed" + "n_episodes")."""
    if not dataset_meta:
        return
    if "episode_seeds" in dataset_meta:  # the expert skips a failed seed and moves on: use the list
        used = {int(s) for s in dataset_meta["episode_seeds"]}
    elif "seed" in dataset_meta and "n_episodes" in dataset_meta:
        used = set(range(int(dataset_meta["seed"]), int(dataset_meta["seed"]) + int(dataset_meta["n_episodes"])))
    else:
        return
    overlap = sorted(int(s) for s in seeds if int(s) in used)
    if overlap:
        raise ValueError(f"evaluation seeds {overlap[:5]}... were used for the demonstrations (seeds {min(used)}..{max(used)}); "
                         f"evaluate on held-out seeds (default: from {EVAL_SEED_START})")


def pusht_obs_adapter(policy: Any) -> tuple[dict[str, Any], Callable[[list[Any]], Any]]:
    """(PushTEnv kwargs, obs_fn) for a PushT policy, from its config's ``features``/``obs_type``."""
    from coursekit.data.features import get_features

    c = policy.config
    if getattr(c, "obs_type", "low_dim") == "image":
        size = tuple(c.vision.image_size)

        def image_obs(obs: list[Any]) -> dict[str, np.ndarray]:
            pixels = np.stack([o["pixels"] for o in obs])  # (B, H, W, 3) uint8
            return {"image": pixels.transpose(0, 3, 1, 2),  # (B, 3, H, W)
                    "agent_pos": np.stack([o["agent_pos"] for o in obs]).astype(np.float32)}  # (B, 2)

        return {"obs_type": "pixels_agent_pos", "obs_size": size}, image_obs
    features = get_features(c.features)
    return {"obs_type": "state"}, lambda obs: features(np.stack(obs))  # (B, 5) -> (B, Do)


def evaluate_pusht(policy: Any, n_episodes: int = 50, seeds: Sequence[int] | None = None, max_steps: int = 300,
                   sampler: str | None = None, num_inference_steps: int | None = None, seed: int = 0,
                   executor_cls: Any = None, executor_factory: Callable[[Callable[[Any], Any]], Any] | None = None,
                   dataset_meta: dict[str, Any] | None = None, progress: bool = True, record: bool = False) -> EvalResult:
    """Evaluate a PushT chunk policy by the paper's protocol (see module docstring).

    Args:
        policy: a ChunkPolicy (DiffusionPolicy, RegressionPolicy, ...) with ``config.features``.
        n_episodes, seeds: episodes to run; default seeds are :func:`heldout_seeds` (100000 + i).
        max_steps: steps per episode (300 in the protocol).
        sampler, num_inference_steps: override the diffusion sampler ("ddim"/"ddpm", steps).
        seed: seeds the torch generator of the sampler's noise (the evaluation is deterministic).
        executor_cls: e.g. a student's RecedingHorizon class (called as cls(predict_chunk,
            n_obs_steps=To, n_action_steps=Ta)); executor_factory: full control instead.
        dataset_meta: demonstrations' meta (default: none); overlapping seeds are refused.
        record: keep states (N, T+1, 7) and actions (N, T, 2) for plots.
    """
    import torch

    from coursekit.envs.pusht import PushTEnv

    seeds = list(seeds) if seeds is not None else heldout_seeds(n_episodes)
    check_seeds_disjoint(seeds, dataset_meta)
    env_kwargs, obs_fn = pusht_obs_adapter(policy)
    generator = torch.Generator().manual_seed(int(seed))
    kwargs = _accepted_kwargs(policy.predict_chunk, {"sampler": sampler, "num_inference_steps": num_inference_steps,
                                                     "generator": generator})
    policy.eval()
    policy.reset()

    def predict_chunk(obs_history: Any) -> Any:
        return policy.predict_chunk(obs_history, **kwargs)

    factory = executor_factory or (lambda pc: policy.make_executor(pc, executor_cls=executor_cls))
    result = rollout(predict_chunk, lambda: PushTEnv(max_episode_steps=max_steps, **env_kwargs), obs_fn, seeds,
                     factory, max_steps=max_steps, progress=progress, record=record,
                     desc=f"eval {getattr(policy, 'policy_type', '')}".strip())
    c = policy.config
    result.info.update({"policy_type": getattr(policy, "policy_type", ""), "max_steps": max_steps,
                        "n_action_steps": c.n_action_steps, "sampling_seed": seed})
    if hasattr(policy, "make_sampler"):  # diffusion: which sampler and how many steps really ran
        used = policy.make_sampler(sampler, num_inference_steps)
        result.info.update({"sampler": sampler or c.sampler, "num_inference_steps": len(used.timesteps),
                            "first_timestep": int(used.timesteps[0])})
    elif hasattr(policy, "integration_info"):  # flow matching: which integrator and how many steps
        result.info.update(policy.integration_info(sampler, num_inference_steps))
    return result
