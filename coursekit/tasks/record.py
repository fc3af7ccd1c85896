"""The task record: everything the library knows about one task, in one frozen dataclass.

A :class:`Task` is plain data plus references: numbers (control rate, episode length), names
(canonical name, command-line aliases, gymnasium id, default features) and the code that
belongs to the task (its env, scripted expert, evaluation figures, replay drawing). Code in
higher layers is named by a ``"module:attribute"`` entry point, imported on first use, as
gymnasium's registry does: registering a task imports no simulator, so ``import coursekit``
stays cheap and the records can sit below every other layer, which all read from them.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

Ref = str | Callable[..., Any]
"""A "module:attribute" entry point (imported on first use) or the callable itself."""


def load(ref: Ref, what: str) -> Callable[..., Any]:
    """The callable an entry point names (a callable is returned as it is)."""
    if callable(ref):
        return ref
    module, sep, attr = str(ref).partition(":")
    if not (sep and module and attr):
        raise ValueError(f"{what} must be a callable or a 'module:attribute' entry point, got {ref!r}")
    return getattr(importlib.import_module(module), attr)


def _is_ref(ref: Any) -> bool:
    return callable(ref) or (isinstance(ref, str) and ref.count(":") == 1 and all(ref.split(":")))


@dataclass(frozen=True)
class ReplayDrawing:
    """How a replay (``coursekit.viz.replay``) draws a task's recorded states."""

    viewer: str
    """Which viewer draws the world: 'pusht' (the planar PushT scene) or 'mujoco' (the env's MuJoCo model)."""
    columns: tuple[int, int | None]
    """[start, stop) of the columns of a recorded evaluation state that the viewer draws (stop None: to the end)."""
    panel_hw: tuple[int, int]
    """(H, W) pixels of one frame in the first/last-frame grid."""
    camera: str | None = None
    """The env camera the frame grid is rendered from ('mujoco' viewer); None for PushT's own renderer."""

    def __post_init__(self) -> None:
        if self.viewer not in ("pusht", "mujoco"):
            raise ValueError(f"replay viewer must be 'pusht' or 'mujoco', got {self.viewer!r}")
        start, stop = self.columns
        if not (isinstance(start, int) and start >= 0 and (stop is None or (isinstance(stop, int) and stop > start))):
            raise ValueError(f"replay columns must be (start >= 0, stop > start or None), got {self.columns!r}")
        if len(self.panel_hw) != 2 or any(not isinstance(v, int) or v < 1 for v in self.panel_hw):
            raise ValueError(f"replay panel_hw must be two positive ints (H, W), got {self.panel_hw!r}")


@dataclass(frozen=True)
class Task:
    """One task (PushT, transfer cube, insertion, ...): the single home of its facts.

    Register a new one with :func:`coursekit.tasks.register_task`; ``coursekit collect``, ``train``,
    ``eval``, the replays and the delay model then take it as they are.
    """

    name: str
    """Canonical name, used in results, dataset meta, ``evaluate`` and replays ('pusht', 'transfer_cube')."""
    gym_id: str
    """Gymnasium id, registered at ``import coursekit`` ('coursekit/PushT-v0')."""
    env: Ref
    """The env class or factory, kwargs -> gymnasium.Env (``max_episode_steps=`` among the kwargs)."""
    control_hz: float
    """Actions per second: PushT 10, the arm pair 50 (as ALOHA)."""
    max_steps: int
    """Steps per episode in the evaluation protocol (and the scripted demonstrations' length)."""
    features: str
    """Default observation features of a policy, a key of ``coursekit.data.features.FEATURES``."""
    aliases: tuple[str, ...] = ()
    """Other names the command line accepts for this task ('aloha-cube')."""
    expert: Ref | None = None
    """Scripted expert: (n_episodes, seed, progress=True, **options) -> EpisodeDataset; None if there is none."""
    expert_options: tuple[str, ...] = ()
    """Keyword options the expert takes beyond those ('action_noise': ``coursekit collect --action-noise``)."""
    demo_episodes: int = 50
    """Demonstrations ``coursekit collect`` generates when not told how many."""
    image_env_kwargs: Callable[[tuple[int, int]], dict[str, Any]] | None = None
    """(H, W) -> env kwargs whose observations are {'pixels', 'agent_pos'} (image policies); None: no images."""
    state_fn: Callable[[Any], Any] | None = None
    """env -> the (S,) state an evaluation records per step; None: ``env.unwrapped.get_state()``."""
    metrics_fn: Callable[[Any], dict[str, Any]] | None = None
    """EvalResult -> the task's own figures in ``result.info`` (from the recorded states); None: none."""
    scores_fn: Callable[[Any], tuple[Any, Any]] | None = None
    """EvalResult -> (score (N,), success (N,)) per episode; None: the max reward and the env's success."""
    replay: ReplayDrawing | None = None
    """How ``coursekit eval --record`` draws the episodes; None: this task has no replay."""

    def __post_init__(self) -> None:
        for field in ("name", "gym_id", "features"):
            value = getattr(self, field)
            if not isinstance(value, str) or not value.strip():
                raise ValueError(f"task {field} must be a non-empty string, got {value!r}")
        if not isinstance(self.aliases, tuple) or not all(isinstance(a, str) and a for a in self.aliases):
            raise ValueError(f"task aliases must be a tuple of non-empty strings, got {self.aliases!r}")
        if not _is_ref(self.env):
            raise ValueError(f"task env must be a callable or a 'module:Class' entry point, got {self.env!r}")
        if self.expert is not None and not _is_ref(self.expert):
            raise ValueError(f"task expert must be None, a callable or a 'module:function' entry point, got {self.expert!r}")
        hz = self.control_hz
        if isinstance(hz, bool) or not isinstance(hz, (int, float)) or not (math.isfinite(hz) and hz > 0):
            raise ValueError(f"task control_hz must be a positive finite number, got {hz!r}")
        for field in ("max_steps", "demo_episodes"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"task {field} must be an int >= 1, got {value!r}")
        if self.replay is not None and not isinstance(self.replay, ReplayDrawing):
            raise ValueError(f"task replay must be a ReplayDrawing or None, got {self.replay!r}")

    @property
    def names(self) -> tuple[str, ...]:
        """The canonical name and the aliases."""
        return (self.name, *self.aliases)

    def make_env(self, **kwargs: Any) -> Any:
        """A new env of this task (``kwargs`` go to the env class, e.g. ``max_episode_steps``)."""
        return load(self.env, f"task {self.name!r} env")(**kwargs)

    def collect(self, n_episodes: int, seed: int, progress: bool = True, **options: Any) -> Any:
        """``n_episodes`` scripted demonstrations from spawn seed ``seed`` on (an EpisodeDataset)."""
        if self.expert is None:
            raise ValueError(f"task {self.name!r} has no scripted expert")
        unknown = sorted(set(options) - set(self.expert_options))
        if unknown:
            raise ValueError(f"the {self.name} expert takes no option {unknown}; it takes {list(self.expert_options)}")
        return load(self.expert, f"task {self.name!r} expert")(n_episodes, seed, progress=progress, **options)
