"""Closed-loop evaluation, the generic part: many seeded episodes in lock-step, one network call per chunk.

:func:`rollout` is policy- and task-agnostic: B environments step together, an executor
(receding horizon, temporal ensembling, or a student's class) turns chunks into actions, and
finished episodes are frozen while the others go on. :func:`evaluate` runs a policy through it
on one task, described by a :class:`TaskAdapter` (``coursekit.evaluate.tasks.RecordAdapter`` reads
it off the task's record in ``coursekit.tasks``): how to build the env, read observations as policy
inputs, record a state per step and score an episode. Everything is seeded, so a run is reproducible.

Execution under an inference delay (chapter 11) is an executor choice like any other::

    evaluate(policy, adapter, seeds, executor_cls=STRATEGIES["rtc"], executor_options={"delay": 2})

(:mod:`coursekit.execution.delay`, :mod:`coursekit.execution.rtc`); real-time chunking also
gets the policy's guided sampler, bound to the same noise generator as every other chunk.

Adding a task is one record (``coursekit.tasks.register_task``); evaluation then takes it as it is.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

import numpy as np
from tqdm.auto import tqdm

from coursekit.evaluate.result import EvalResult, check_seeds_disjoint


class TaskAdapter(Protocol):
    """What :func:`evaluate` needs to know about a task (PushT, the arm pair, ...)."""

    task: str
    """Task name: 'pusht', 'transfer_cube', 'insertion'."""
    max_steps: int
    """Protocol steps per episode (the task record's ``max_steps``)."""
    record_always: bool
    """True when :meth:`metrics` needs the recorded states (the arm pair's stages)."""

    def make_env(self, max_steps: int) -> Any:
        """One gymnasium environment with a ``max_steps`` step limit."""

    def obs_fn(self, observations: list[Any]) -> Any:
        """B raw env observations -> the policy's per-step input (B, ...) (array or dict)."""

    def state_fn(self, env: Any) -> np.ndarray:
        """The state recorded per step (S,)."""

    def metrics(self, result: EvalResult) -> dict[str, Any]:
        """Task-specific figures for ``result.info``."""

    def replay_states(self, result: EvalResult) -> np.ndarray:
        """(N, T + 1, S') states a replay draws: PushT [agent x, y, block x, y, angle]; arm pair MuJoCo qpos."""

    def episode_scores(self, result: EvalResult) -> tuple[np.ndarray, np.ndarray]:
        """(score (N,), success (N,)) of each episode, as the task's protocol reports them."""


def rollout(predict_chunk: Callable[[Any], Any], make_env: Callable[[], Any], obs_fn: Callable[[list[Any]], Any],
            seeds: Sequence[int], executor_factory: Callable[[Callable[[Any], Any]], Any], max_steps: int,
            progress: bool = True, record: bool = False, state_fn: Callable[[Any], np.ndarray] | None = None,
            desc: str = "eval") -> EvalResult:
    """Run one episode per seed, all environments in lock-step, and collect the outcomes.

    Args:
        predict_chunk: (B, To, ...) observation history -> (B, Tp, Da) chunk (raw units).
        make_env: builds one gymnasium environment (called len(seeds) times).
        obs_fn: list of B raw env observations -> the policy's per-step input (B, ...) (array or dict).
        seeds: reset seed of each episode.
        executor_factory: predict_chunk -> executor with ``reset(obs)`` / ``act(obs) -> (B, Da)``.
        max_steps: step limit per episode (a task's protocol: its record's ``max_steps``).
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
    executor = executor_factory(timed)  # first: a bad executor option fails before any env is built
    envs = [make_env() for _ in seeds]
    obs = [env.reset(seed=int(s))[0] for env, s in zip(envs, seeds)]
    executor.reset(obs_fn(obs))
    episodes = _LockStep(envs, state_fn, record)
    bar = tqdm(total=max_steps, desc=desc, disable=not progress, dynamic_ncols=True)
    try:
        for _ in range(max_steps):
            act = executor.act(obs_fn(obs))
            episodes.step(obs, act.detach().cpu().numpy() if hasattr(act, "detach") else np.asarray(act))
            bar.update(1)
            bar.set_postfix(score=f"{episodes.max_reward.mean():.3f}", done=f"{int(episodes.done.sum())}/{len(envs)}")
            if episodes.done.all():
                break
        bar.total = bar.n  # finished (all done, or max_steps): the bar ends full and green, not red
    finally:
        bar.close()
        for env in envs:
            env.close()
    states, actions = episodes.recorded() if record else (None, None)
    return EvalResult(seeds=[int(s) for s in seeds], max_reward=episodes.max_reward, success=episodes.success,
                      length=episodes.length, seconds=time.perf_counter() - start, chunk_calls=timing["calls"],
                      chunk_seconds=timing["seconds"], states=states, actions=actions,
                      info={"executor": type(executor).__name__})


class _LockStep:
    """B environments stepped together: each one's best reward, success, length and done flag (N,),
    and, when recording, its states and actions; a finished episode is frozen while the others go on."""

    def __init__(self, envs: list[Any], state_fn: Callable[[Any], np.ndarray], record: bool) -> None:
        n = len(envs)
        self.envs, self.state_fn, self.record = envs, state_fn, record
        self.max_reward = np.zeros(n)
        self.success = np.zeros(n, dtype=bool)
        self.length = np.zeros(n, dtype=np.int64)
        self.done = np.zeros(n, dtype=bool)
        self.states = [[state_fn(e)] for e in envs] if record else None
        self.actions: list[list[np.ndarray]] | None = [[] for _ in envs] if record else None
        self.action_dim = 0

    def step(self, obs: list[Any], act: np.ndarray) -> None:
        """Step each unfinished env ``i`` with ``act[i]`` (``act``: (B, Da)); ``obs[i]`` becomes its new observation."""
        self.action_dim = act.shape[-1]
        for i, env in enumerate(self.envs):
            if self.done[i]:
                continue
            obs[i], reward, terminated, truncated, info = env.step(act[i])
            self.max_reward[i] = max(self.max_reward[i], float(reward))
            self.success[i] |= bool(info.get("is_success", terminated))
            self.length[i] += 1
            self.done[i] = terminated or truncated
            if self.record:
                self.states[i].append(self.state_fn(env))
                self.actions[i].append(np.asarray(act[i], dtype=np.float64))

    def recorded(self) -> tuple[np.ndarray, np.ndarray]:
        """(states (N, T + 1, S), actions (N, T, Da)): finished episodes padded with their last state/action."""
        t_max = max(len(a) for a in self.actions)
        states = np.stack([np.stack(s + [s[-1]] * (t_max + 1 - len(s))) for s in self.states])
        actions = np.stack([np.stack(a + [a[-1]] * (t_max - len(a))) if a else np.zeros((t_max, self.action_dim))
                            for a in self.actions])
        return states, actions


def evaluate(policy: Any, adapter: TaskAdapter, seeds: Sequence[int], *, max_steps: int | None = None,
             sampling: Mapping[str, Any] | None = None, seed: int = 0, executor_cls: Any = None,
             executor_options: Mapping[str, Any] | None = None,
             executor_factory: Callable[[Callable[[Any], Any]], Any] | None = None,
             dataset_meta: dict[str, Any] | None = None, progress: bool = True, record: bool = False) -> EvalResult:
    """Run ``policy`` on ``adapter``'s task from each of ``seeds``; the one evaluation flow of every policy.

    Args:
        policy: a ChunkPolicy; ``policy.predict_chunk(obs, generator=g, **sampling)`` is called.
        adapter: the task (:class:`TaskAdapter`).
        seeds: reset seed of each episode (held-out: from 100000); overlap with ``dataset_meta``'s
            demonstration seeds is refused.
        max_steps: steps per episode (default: the task's protocol).
        sampling: the policy's sampling options (diffusion: sampler, num_inference_steps), checked first.
        seed: seeds the generator of the policy's sampling noise (the evaluation is deterministic).
        executor_cls: replaces the policy's default executor class (built with ``from_spec``), e.g. a
            student's or a delayed one of chapter 11 (``coursekit.execution.rtc.STRATEGIES``);
            ``executor_options``: its other ``from_spec`` keywords (``delay``; RTC's ``schedule``,
            ``max_guidance``, ``prefix``); ``executor_factory``: ``predict_chunk -> executor`` instead.
        record: keep per-step states and actions (always on when the task's metrics need them).
    ``result.info`` names the executor and its options, and what a delayed one logged (:func:`_executor_log`).
    """
    import torch

    sampling = dict(sampling or {})
    policy.check_sampling(sampling)
    described = policy.describe_sampling(**sampling)
    seeds = [int(s) for s in seeds]
    check_seeds_disjoint(seeds, dataset_meta)
    max_steps = adapter.max_steps if max_steps is None else int(max_steps)
    generator = torch.Generator().manual_seed(int(seed))
    options = dict(executor_options or {})
    guided = _guided_sampler(policy, executor_cls, generator, sampling)
    extra = {"predict_inpainted": guided} if guided is not None else {}
    policy.eval()
    policy.reset()

    def predict_chunk(obs_history: Any) -> Any:
        return policy.predict_chunk(obs_history, generator=generator, **sampling)

    made: list[Any] = []  # the executor rollout builds, for its logs

    def factory(pc: Callable[[Any], Any]) -> Any:
        made.append(policy.make_executor(pc, executor_cls=executor_cls, **options, **extra))
        return made[-1]

    record = record or adapter.record_always
    result = rollout(predict_chunk, lambda: adapter.make_env(max_steps), adapter.obs_fn, seeds,
                     executor_factory or factory, max_steps=max_steps, progress=progress, record=record,
                     state_fn=adapter.state_fn, desc=f"eval {policy.policy_type} {adapter.task}")
    spec = policy.execution_spec()
    result.info.update({"policy_type": policy.policy_type, "task": adapter.task, "max_steps": max_steps,
                        "sampling_seed": seed, "n_action_steps": spec.n_action_steps,
                        "temporal_ensembling": spec.temporal_ensembling,
                        "ensemble_decay": spec.ensemble_decay if spec.temporal_ensembling else None,
                        **described, **options, **adapter.metrics(result), **_executor_log(made, guided, record)})
    return result


def _executor_log(made: list[Any], guided: _GuidedSampler | None, record: bool) -> dict[str, Any]:
    """A delayed executor's chunk switch steps (``switches``, when recording); RTC's guided calls and seconds."""
    log: dict[str, Any] = {}
    if record and made and hasattr(made[-1], "switches"):
        log["switches"] = list(made[-1].switches)
    if guided is not None:
        log.update({"guided_calls": guided.calls, "guided_seconds": round(guided.seconds, 3)})
    return log


class _GuidedSampler:
    """``policy.predict_inpainted`` bound to the evaluation's generator and sampling options, timed."""

    def __init__(self, policy: Any, generator: Any, sampling: Mapping[str, Any]) -> None:
        self.policy, self.generator, self.sampling = policy, generator, sampling
        self.calls, self.seconds = 0, 0.0

    def __call__(self, obs_history: Any, target: Any, weights: Any, **options: Any) -> Any:
        t0 = time.perf_counter()
        out = self.policy.predict_inpainted(obs_history, target, weights, generator=self.generator,
                                            **options, **self.sampling)
        self.seconds += time.perf_counter() - t0
        self.calls += 1
        return out


def _guided_sampler(policy: Any, executor_cls: Any, generator: Any, sampling: Mapping[str, Any]) -> _GuidedSampler | None:
    """The guided sampler real-time chunking needs (None for any other executor); refuses a policy without one."""
    from coursekit.execution.rtc import RealTimeChunking

    if not (isinstance(executor_cls, type) and issubclass(executor_cls, RealTimeChunking)):
        return None
    if not callable(getattr(policy, "predict_inpainted", None)):
        raise ValueError(f"{executor_cls.__name__} inpaints during denoising/integration: it needs a diffusion or "
                         f"flow policy (one with predict_inpainted), not {policy.policy_type!r}")
    return _GuidedSampler(policy, generator, sampling)
