"""Teleoperation: record PushT demonstrations by hand, in the same format as the scripted expert's.

The Diffusion Policy paper's PushT data were collected by people pushing the T with a mouse
(Chi et al. 2023, Sec. 5: 206 human demonstrations); that is where its two-routes multimodality
comes from. :class:`TeleopRecorder` is the part that does not care where the targets come from:
feed it one pusher target per control step (10 Hz) and it steps a real ``PushTEnv`` and records
the episode. The JupyterLab widget (``coursekit.viz.teleop_widget``) feeds it mouse positions;
tests and fast-mode notebooks feed it a scripted path (:func:`path_targets`).

A recording is an ``EpisodeDataset`` with the SAME arrays as ``coursekit collect pusht``
(row t = the state BEFORE action t):

    "state"    (N, 5) float64 [agent_x, agent_y, block_x, block_y, block_angle UNWRAPPED]
    "action"   (N, 2) float64 pusher target (x, y) in [0, 512]
    "coverage" (N,)   float64 coverage of the row's state
    "phase"    (N,)   int8 1 travel (pusher clear of the T), 2 push (touching it), 3 rest
                      (after the first success); 0 settle is the expert's only

so ``coursekit train --data`` takes it as it is, alone or mixed with expert data (:func:`mix`).

Exact replay: ``meta["episode_resets"]`` keeps how each episode was reset (``{"seed": s}`` or
``{"reset_to_state": [...]}``); :func:`replay` resets a FRESH env the same way and applies the
recorded actions, which reproduces every recorded state bit for bit. (Placing the first state
with ``PushTEnv.set_state`` instead is not exact: pymunk keeps hidden solver state from the
reset's substep, see ``PushTEnv.set_state``.)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from coursekit.data.episodes import DatasetError, EpisodeDataset
from coursekit.envs import pusht_geometry as geo
from coursekit.envs.pusht import PushTEnv
from coursekit.tasks.pusht import PUSHT

__all__ = ["TeleopConfig", "TeleopRecorder", "mix", "path_targets", "replay", "route_side"]

SOURCE = "coursekit.teleop"
"""``meta["expert"]`` of a hand-recorded dataset (the scripted one says its planner's name)."""
TRAVEL, PUSH, REST = 1, 2, 3
PHASE_NAMES = ("settle", "travel", "push", "rest")


@dataclass
class TeleopConfig:
    """Settings of a teleoperation session."""

    max_steps: int = PUSHT.max_steps
    """An episode stops itself after this many control steps (default: the evaluation protocol's length)."""
    rest_steps: int = 5
    """Steps still recorded after the first success (coverage > 0.95) before the episode stops
    itself, as the expert's rest steps: policies learn when to stop."""
    contact_margin: float = 1.0
    """A pusher whose edge is within this many px of the T is pushing (phase 2)."""

    def __post_init__(self) -> None:
        for name in ("max_steps", "rest_steps"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < (1 if name == "max_steps" else 0):
                raise ValueError(f"{name} must be an int >= {1 if name == 'max_steps' else 0}, got {value!r}")
        if not (math.isfinite(self.contact_margin) and self.contact_margin >= 0):
            raise ValueError(f"contact_margin must be a finite number of px >= 0, got {self.contact_margin!r}")


def _touching(state: np.ndarray, margin: float) -> bool:
    """Whether the pusher of state (5,) is within ``margin`` px of the T's outline or inside it."""
    import shapely

    t = geo.t_shape(state[2:5])
    return bool(t.distance(shapely.Point(state[0], state[1])) <= geo.AGENT_RADIUS + margin)


class TeleopRecorder:
    """Steps a real PushT env from one target per control step and records kept episodes.

    ``start()`` resets the env (the next seed, or ``reset_state``), ``step(target)`` applies one
    pusher target (one 10 Hz control step), ``stop()`` keeps the episode (and writes ``path``,
    atomically, when one was given), ``discard()`` drops it. An episode also stops by itself
    ``rest_steps`` steps after its first success, or after ``max_steps`` steps.

    Args:
        path: optional ``.npz`` the kept episodes are written to after every ``stop()``. An
            existing file must be an earlier teleoperation recording: its episodes are loaded and
            new ones are appended (a file of any other kind is refused, never overwritten).
        first_seed: seed of the first seeded reset; each seeded episode uses the next one.
        reset_state: optional (5,) [ax, ay, bx, by, angle]: every episode starts there instead
            (the env's ``reset_to_state``, legacy order), e.g. ``TWO_WAY_START``.
        config: :class:`TeleopConfig`.
    """

    def __init__(self, path: str | Path | None = None, first_seed: int = 0, reset_state: Sequence[float] | None = None,
                 config: TeleopConfig | None = None):
        if isinstance(first_seed, bool) or not isinstance(first_seed, (int, np.integer)) or first_seed < 0:
            raise ValueError(f"first_seed must be a non-negative int, got {first_seed!r}")
        self.config = config or TeleopConfig()
        self.reset_state = None if reset_state is None else PushTEnv.check_state(reset_state)
        if self.reset_state is not None and self.reset_state.shape != (5,):
            raise ValueError(f"reset_state must be (5,) [ax, ay, bx, by, angle], got shape {self.reset_state.shape}")
        self.path = None if path is None else Path(path)
        self.episodes: list[dict[str, np.ndarray]] = []
        self.resets: list[dict[str, Any]] = []
        self.success_steps: list[int | None] = []
        self.next_seed = int(first_seed)
        if self.path is not None and self.path.exists():
            self._load_existing(self.path)
        self.env = PushTEnv(obs_type="state", max_episode_steps=self.config.max_steps)
        self._rows: list[tuple[np.ndarray, np.ndarray, float, int]] | None = None
        self._reset: dict[str, Any] = {}
        self._success_step: int | None = None
        self.coverage = 0.0
        self.state = self.env.get_state()[:5]

    def _load_existing(self, path: Path) -> None:
        old = EpisodeDataset.load(path)
        if old.meta.get("expert") != SOURCE:
            raise DatasetError(f"{str(path)!r} exists and is not a teleoperation recording (its meta expert is "
                               f"{old.meta.get('expert')!r}, expected {SOURCE!r}); choose another path")
        self.episodes = [old.episode(i) for i in range(old.n_episodes)]
        self.resets = list(old.meta["episode_resets"])
        self.success_steps = list(old.meta["success_steps"])
        seeds = [r["seed"] for r in self.resets if "seed" in r]
        self.next_seed = max([self.next_seed, *(s + 1 for s in seeds)])

    # ---- one episode --------------------------------------------------------------------
    @property
    def recording(self) -> bool:
        """True between ``start()`` and the episode's end."""
        return self._rows is not None

    @property
    def n_steps(self) -> int:
        """Control steps recorded in the current episode."""
        return len(self._rows) if self._rows is not None else 0

    def next_reset(self) -> dict[str, Any]:
        """How the next episode will be reset: ``{"seed": s}`` or ``{"reset_to_state": [...]}``."""
        if self.reset_state is not None:
            return {"reset_to_state": self.reset_state.tolist()}
        return {"seed": self.next_seed}

    def preview(self) -> np.ndarray:
        """Reset the env to where the next episode will start, without recording; its state (5,)."""
        if self.recording:
            raise RuntimeError("an episode is being recorded: stop() or discard() it first")
        return self._reset_env(self.next_reset())

    def _reset_env(self, reset: dict[str, Any]) -> np.ndarray:
        _, info = _reset(self.env, reset)
        self.coverage = float(info["coverage"])
        self.state = self.env.get_state()[:5]
        return self.state

    def start(self) -> np.ndarray:
        """Reset the env for a new episode; returns its first state (5,). Drops an unfinished one."""
        self._reset = self.next_reset()
        if "seed" in self._reset:
            self.next_seed += 1
        self._reset_env(self._reset)
        self._rows, self._success_step = [], None
        return self.state

    def step(self, target: Sequence[float]) -> bool:
        """Apply one pusher target (2,) for one control step; returns True while still recording."""
        if self._rows is None:
            raise RuntimeError("not recording: call start() first")
        action = np.clip(np.asarray(PushTEnv.check_action(target), dtype=np.float64), 0.0, geo.WORLD_SIZE)
        state = self.env.get_state()[:5]
        if self._success_step is not None:
            phase = REST
        else:
            phase = PUSH if _touching(state, self.config.contact_margin) else TRAVEL
        self._rows.append((state, action, self.coverage, phase))
        _, _, terminated, _, info = self.env.step(action)
        self.coverage = float(info["coverage"])
        self.state = self.env.get_state()[:5]
        if terminated and self._success_step is None:
            self._success_step = len(self._rows)
        rested = self._success_step is not None and len(self._rows) >= self._success_step + self.config.rest_steps
        if rested or len(self._rows) >= self.config.max_steps:
            self.stop()
        return self.recording

    def stop(self) -> int | None:
        """End the episode and keep it; returns its index (None when it had no step)."""
        rows, self._rows = self._rows, None
        if not rows:
            return None
        states, actions, coverage, phases = zip(*rows)
        self.episodes.append({"state": np.stack(states), "action": np.stack(actions),
                              "coverage": np.asarray(coverage, dtype=np.float64),
                              "phase": np.asarray(phases, dtype=np.int8)})
        self.resets.append(dict(self._reset))
        self.success_steps.append(self._success_step)
        if self.path is not None:
            self.save(self.path)
        return len(self.episodes) - 1

    def discard(self) -> None:
        """End the episode without keeping it."""
        self._rows = None

    def record(self, targets: np.ndarray) -> int | None:
        """A whole episode from a scripted path: ``start()``, one ``step`` per target (T, 2)
        until the episode ends by itself, then ``stop()``. Returns the kept episode's index."""
        self.start()
        for target in np.asarray(targets, dtype=np.float64):
            if not self.step(target):
                return len(self.episodes) - 1
        return self.stop()

    # ---- the kept episodes --------------------------------------------------------------
    def dataset(self) -> EpisodeDataset:
        """The kept episodes as an ``EpisodeDataset`` (the same arrays as ``coursekit collect pusht``)."""
        import coursekit

        if not self.episodes:
            raise DatasetError("no episode kept yet: record one (start, step, stop) first")
        meta = {
            "env_id": PUSHT.gym_id, "obs_type": "state", "expert": SOURCE,
            "n_episodes": len(self.episodes), "control_hz": PUSHT.control_hz,
            "episode_resets": self.resets,
            "episode_seeds": [r["seed"] for r in self.resets if "seed" in r],
            "success_steps": self.success_steps, "route_choices": [[] for _ in self.episodes],
            "routes": [route_side(ep["state"], ep["phase"]) for ep in self.episodes],
            "teleop_config": asdict(self.config), "rest_steps": self.config.rest_steps,
            "phase_names": list(PHASE_NAMES),
            "state_columns": ["agent_x", "agent_y", "block_x", "block_y", "block_angle_unwrapped"],
            "action_columns": ["target_x", "target_y"],
            "coursekit_version": coursekit.__version__,
        }
        return EpisodeDataset.from_episodes(self.episodes, meta)

    def save(self, path: str | Path | None = None) -> Path:
        """Write the kept episodes (atomically) to ``path`` (default: the recorder's)."""
        target = Path(path) if path is not None else self.path
        if target is None:
            raise ValueError("no path: give save() a path or the recorder a path=")
        return self.dataset().save(target)


def _reset(env: PushTEnv, reset: dict[str, Any]):
    """Reset ``env`` as an episode's ``meta["episode_resets"]`` entry says."""
    if "seed" in reset:
        return env.reset(seed=int(reset["seed"]))
    if "reset_to_state" in reset:
        return env.reset(options={"reset_to_state": np.asarray(reset["reset_to_state"], dtype=np.float64)})
    raise ValueError(f"an episode reset must hold 'seed' or 'reset_to_state', got {reset!r}")


def replay(dataset: EpisodeDataset, index: int) -> np.ndarray:
    """Replay episode ``index`` of a recording in a FRESH env: (T, 5) states before each action.

    Reset exactly as recorded (``meta["episode_resets"]``), then the recorded actions: the
    result equals ``dataset.episode(index)["state"]`` bit for bit.
    """
    resets = dataset.meta.get("episode_resets")
    if resets is None or len(resets) != dataset.n_episodes:
        raise DatasetError(f"the dataset has no per-episode resets (meta episode_resets: {resets!r}); "
                           "only teleoperation recordings can be replayed this way")
    episode = dataset.episode(index)
    env = PushTEnv(obs_type="state", max_episode_steps=max(1, len(episode["action"])))
    _reset(env, resets[index])
    states = []
    for action in episode["action"]:
        states.append(env.get_state()[:5])
        env.physics_step(action)
    env.close()
    return np.array(states).reshape(-1, 5)  # (T, 5)


def route_side(states: np.ndarray, phases: np.ndarray | None = None, min_turn: float = math.pi / 4) -> str | None:
    """Which way round the T the pusher went before its first push: "cw", "ccw" or None.

    The pusher's swept angle about the T's centre of gravity, summed over the steps before the
    first contact (phase 2; the whole episode when there is none). Clockwise is as seen on the
    screen (y down), the expert's convention. Less than ``min_turn`` radians either way: None.
    """
    states = np.asarray(states, dtype=np.float64)
    end = len(states)
    if phases is not None:
        pushes = np.flatnonzero(np.asarray(phases) == PUSH)
        end = int(pushes[0]) + 1 if len(pushes) else end
    if end < 2:
        return None
    # The T does not move before the first contact (it moves only while pushed), so its first pose
    # holds for the whole leg: the same measure as the expert's path_sweep.
    swept = geo.swept_angle(states[:end, :2], states[0, 2:5])
    if abs(swept) < min_turn:
        return None
    return "cw" if swept > 0 else "ccw"


def path_targets(waypoints: Sequence[Sequence[float]], speed: float = 20.0, hold: int = 0) -> np.ndarray:
    """A hand's path as one target per control step: straight lines through ``waypoints`` (W, 2)
    at ``speed`` px per step, then ``hold`` more steps at the last point. (T, 2)."""
    pts = np.asarray(waypoints, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 1 or not np.all(np.isfinite(pts)):
        raise ValueError(f"waypoints must be a finite (W, 2) array of points, got {waypoints!r}")
    if not (math.isfinite(speed) and speed > 0):
        raise ValueError(f"speed must be > 0 px per step, got {speed!r}")
    out = [pts[0]]
    for a, b in zip(pts[:-1], pts[1:]):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / speed)))
        out.extend(a + (b - a) * (i / n) for i in range(1, n + 1))
    out.extend([pts[-1]] * int(hold))
    return np.clip(np.array(out), 0.0, geo.WORLD_SIZE)  # (T, 2)


def mix(*datasets: EpisodeDataset) -> EpisodeDataset:
    """One dataset from several (e.g. the expert's and yours) with the arrays they all share.

    ``meta``: the first dataset's, with ``n_episodes`` and ``episode_seeds`` (the union, so the
    evaluation still refuses every seed any part used), and ``sources``: [expert, n_episodes]
    per part.
    """
    if not datasets:
        raise ValueError("mix needs at least one dataset")
    keys = sorted(set.intersection(*(set(d.arrays) for d in datasets)))
    if "state" not in keys or "action" not in keys:
        raise DatasetError(f"the datasets share only arrays {keys}; mixing needs 'state' and 'action'")
    episodes = [{k: d.episode(i)[k] for k in keys} for d in datasets for i in range(d.n_episodes)]
    meta = dict(datasets[0].meta)
    seeds = sorted({int(s) for d in datasets for s in d.meta.get("episode_seeds", [])})
    meta.update({"n_episodes": len(episodes), "episode_seeds": seeds,
                 "sources": [[d.meta.get("expert"), d.n_episodes] for d in datasets]})
    for key in ("episode_resets", "route_choices", "success_steps", "finish_steps", "episode_noise", "routes"):
        meta.pop(key, None)  # per-episode lists of one part would no longer line up
    return EpisodeDataset.from_episodes(episodes, meta)
