"""Gymnasium environments for the ALOHA arm pair: transfer cube and insertion.

    env = gymnasium.make("coursekit/AlohaTransferCube-v0")           # or AlohaInsertionEnv()
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(action)      # action (14,)

Action (14,) float: absolute joint targets for the position servos, in the layout of
``coursekit.envs.aloha.model`` ([left 6 joints, left gripper g, right 6 joints, right gripper g]).
One step = 10 physics steps of 2 ms (the arm pair's 50 Hz control, ``coursekit.tasks.aloha.CONTROL_HZ``).
Joint targets outside the joint ranges and gripper commands outside [-0.34, 1.0] are CLIPPED to
those bounds (the action space's low/high); an action of the wrong shape or with NaN/inf raises
ValueError.

Observations (``obs_type``):
    "state"  (default) dict: "qpos" (14,) joint angles + normalised grippers,
                             "qvel" (14,) their velocities,
                             "env_state" (7,) cube or (14,) peg + socket poses [x y z qw qx qy qz].
    "pixels" dict: "qpos" (14,), "qvel" (14,), "pixels" (H, W, 3) uint8 from the "top" camera.

Reward: the published stage (0-4) of the current state. ``info`` carries "stage", "max_stage",
"is_success" (lenient, published: max_stage == 4), "strict_success" (the current state is a
finished task; read it at the last step), "env_state" and "sim_unstable".
Episodes are truncated after ``max_episode_steps`` (default ``EPISODE_STEPS``, 8 s); ``terminated`` is True only when
the simulation became unstable (NaN state): the physics is then restored to the last good state,
``info["sim_unstable"]`` is True, and the episode must be reset.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import mujoco
import numpy as np
from gymnasium import spaces

from coursekit.envs.aloha.model import (
    N_SUBSTEPS,
    START_ARM_QPOS,
    START_FINGER,
    ArmPairIndex,
    action_bounds,
    load_model,
    start_qpos14,
)
from coursekit.envs.aloha.render import CameraRenderer
from coursekit.envs.aloha.tasks import TASKS, AlohaTask
from coursekit.envs.checks import check_reset_args, finite_array
from coursekit.envs.image_size import size_hw
from coursekit.tasks.aloha import CONTROL_HZ, EPISODE_STEPS, INSERTION, TRANSFER_CUBE

OBS_TYPES = ("state", "pixels")


class AlohaEnv(gymnasium.Env):
    """The arm pair with one task's objects, under joint-position control.

    Args:
        task: the arm-pair task's name, "transfer_cube" or "insertion" (``coursekit.tasks.aloha``).
        obs_type: "state" or "pixels" (see the module docstring).
        render_mode: None or "rgb_array" (``render()`` returns the ``camera`` image).
        render_size: image size for "pixels" observations and ``render()``: int or (H, W).
        camera: camera used for "pixels" and ``render()``: "top", "angle" or "front_close".
        max_episode_steps: control steps before truncation (default: the protocol's ``EPISODE_STEPS``, 8 s).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": CONTROL_HZ}

    def __init__(self, task: str = TRANSFER_CUBE.name, obs_type: str = "state", render_mode: str | None = None,
                 render_size: int | tuple[int, int] = (240, 320), camera: str = "top",
                 max_episode_steps: int = EPISODE_STEPS) -> None:
        if task not in TASKS:
            raise ValueError(f"unknown task {task!r}; expected one of {sorted(TASKS)}")
        if obs_type not in OBS_TYPES:
            raise ValueError(f"obs_type must be one of {OBS_TYPES}, got {obs_type!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be >= 1, got {max_episode_steps}")
        self.task_name = task
        self.obs_type = obs_type
        self.render_mode = render_mode
        self.render_size = size_hw(render_size, "render_size")
        self.camera = camera
        self.max_episode_steps = max_episode_steps

        self.model = load_model(task)
        self.data = mujoco.MjData(self.model)
        self.index = ArmPairIndex.from_model(self.model)
        self.task: AlohaTask = TASKS[task](self.model)
        cams = {self.model.camera(i).name for i in range(self.model.ncam)}
        if camera not in cams:
            raise ValueError(f"unknown camera {camera!r}; expected one of {sorted(cams)}")
        self._renderer: CameraRenderer | None = None

        low, high = action_bounds(self.model)
        self.action_space = spaces.Box(low=low, high=high, dtype=np.float64)
        vec = spaces.Box(-np.inf, np.inf, shape=(14,), dtype=np.float64)
        obs_spaces: dict[str, spaces.Space] = {"qpos": vec, "qvel": vec}
        if obs_type == "state":
            obs_spaces["env_state"] = spaces.Box(-np.inf, np.inf, shape=(self.task.env_state_dim,), dtype=np.float64)
        else:
            obs_spaces["pixels"] = spaces.Box(0, 255, shape=(*self.render_size, 3), dtype=np.uint8)
        self.observation_space = spaces.Dict(obs_spaces)

        self._t = 0
        self._max_stage = 0

    # ---- gymnasium API --------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict, dict]:
        """Start pose, objects spawned from ``self.np_random`` (or ``options["env_state"]``)."""
        options = check_reset_args(seed, options, {"env_state": "object poses, the task's env_state vector"},
                                   type(self).__name__)
        env_state = None  # checked before anything changes: a refused reset leaves the episode as it was
        if options.get("env_state") is not None:
            env_state = self.task.check_env_state(finite_array(options["env_state"], (self.task.env_state_dim,),
                                                               "options['env_state']", "[x y z qw qx qy qz] per object"),
                                                  "options['env_state']")
        super().reset(seed=seed)
        mujoco.mj_resetData(self.model, self.data)
        self.index.set_arm_pose(self.data, np.concatenate([START_ARM_QPOS, START_ARM_QPOS]), START_FINGER)
        if env_state is None:
            env_state = self.task.spawn(self.np_random)
        self.task.set_env_state(self.data, env_state)
        self.index.set_action(self.data, start_qpos14())
        mujoco.mj_forward(self.model, self.data)
        self._t = 0
        self._max_stage = self.task.stage(self.data)
        return self._obs(), self._info(unstable=False)

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        """One control step with a (14,) action (absolute joint targets + gripper commands)."""
        action = finite_array(action, (14,), "action", "[left 6 joints, left g, right 6 joints, right g]")
        action = np.clip(action, self.action_space.low, self.action_space.high)  # documented clip
        self.index.set_action(self.data, action)
        good_qpos, good_qvel = self.data.qpos.copy(), self.data.qvel.copy()
        warnings_before = self._instability_warnings()
        mujoco.mj_step(self.model, self.data, nstep=N_SUBSTEPS)
        self._t += 1
        # MuJoCo resets the state itself when it meets NaN/inf accelerations and only counts a
        # warning, so check both the numbers and the warning counters.
        unstable = (self._instability_warnings() > warnings_before
                    or not (np.all(np.isfinite(self.data.qpos)) and np.all(np.isfinite(self.data.qvel))))
        if unstable:  # restore the last finite state so the observation stays valid
            self.set_physics_state(good_qpos, good_qvel)
        stage = self.task.stage(self.data)
        self._max_stage = max(self._max_stage, stage)
        truncated = self._t >= self.max_episode_steps
        return self._obs(), float(stage), unstable, truncated and not unstable, self._info(unstable, stage)

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        return self.render_camera(self.camera)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # ---- beyond gymnasium -----------------------------------------------------------------
    @property
    def elapsed_steps(self) -> int:
        """Control steps since the last reset."""
        return self._t

    def render_camera(self, camera: str = "top", size: int | tuple[int, int] | None = None) -> np.ndarray:
        """(H, W, 3) uint8 image of the current state from ``camera`` (default size: render_size)."""
        h, w = size_hw(size, "size") if size is not None else self.render_size
        if self._renderer is None or (self._renderer.height, self._renderer.width) != (h, w):
            self.close()
            self._renderer = CameraRenderer(self.model, h, w)
        # mj_step leaves the kinematics one substep behind qpos; recompute them so that an image
        # is a function of the physics state alone (a stored state re-renders identically).
        mujoco.mj_forward(self.model, self.data)
        return self._renderer.render(self.data, camera)

    def get_physics_state(self) -> dict[str, np.ndarray]:
        """Full MuJoCo state: "physics_qpos" (nq,), "physics_qvel" (nv,), "ctrl" (nu,) copies."""
        return {"physics_qpos": self.data.qpos.copy(), "physics_qvel": self.data.qvel.copy(),
                "ctrl": self.data.ctrl.copy()}

    def set_physics_state(self, qpos: np.ndarray, qvel: np.ndarray | None = None, ctrl: np.ndarray | None = None) -> None:
        """Set the full MuJoCo state (e.g. a dataset's "physics_qpos" row) and update kinematics.

        Use it to render images after the fact: ``env.set_physics_state(q); env.render_camera()``.
        """
        qpos = np.asarray(qpos, dtype=np.float64)
        if qpos.shape != (self.model.nq,) or not np.all(np.isfinite(qpos)):
            raise ValueError(f"qpos must be finite with shape ({self.model.nq},), got shape {qpos.shape}")
        self.data.qpos[:] = qpos
        if qvel is not None:
            qvel = np.asarray(qvel, dtype=np.float64)
            if qvel.shape != (self.model.nv,):
                raise ValueError(f"qvel must have shape ({self.model.nv},), got {qvel.shape}")
            self.data.qvel[:] = qvel
        else:
            self.data.qvel[:] = 0.0
        if ctrl is not None:
            self.data.ctrl[:] = np.asarray(ctrl, dtype=np.float64).reshape(self.model.nu)
        mujoco.mj_forward(self.model, self.data)

    def stage(self) -> int:
        """Published reward stage (0-4) of the current state."""
        return self.task.stage(self.data)

    def strict_success(self) -> bool:
        """Strict success of the current state (meaningful at the end of an episode)."""
        return self.task.strict_success(self.data)

    # ---- internals ------------------------------------------------------------------------
    def _instability_warnings(self) -> int:
        w = self.data.warning
        return int(sum(w[i].number for i in (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQPOS,
                                             mujoco.mjtWarning.mjWARN_BADQVEL)))

    def _obs(self) -> dict[str, np.ndarray]:
        obs = {"qpos": self.index.qpos14(self.data), "qvel": self.index.qvel14(self.data)}
        if self.obs_type == "state":
            obs["env_state"] = self.task.env_state(self.data)
        else:
            obs["pixels"] = self.render_camera("top")
        return obs

    def _info(self, unstable: bool, stage: int | None = None) -> dict[str, Any]:
        return {
            "stage": self.task.stage(self.data) if stage is None else stage,
            "max_stage": self._max_stage,
            "is_success": self._max_stage == 4,
            "strict_success": self.task.strict_success(self.data),
            "env_state": self.task.env_state(self.data),
            "sim_unstable": unstable,
        }


class AlohaTransferCubeEnv(AlohaEnv):
    """Transfer cube (``coursekit/AlohaTransferCube-v0``): right arm picks, left arm receives."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(task=TRANSFER_CUBE.name, **kwargs)


class AlohaInsertionEnv(AlohaEnv):
    """Insertion (``coursekit/AlohaInsertion-v0``): peg (right arm) into socket (left arm)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(task=INSERTION.name, **kwargs)


def render_physics_states(task: str, physics_qpos, size: tuple[int, int], camera: str = "top") -> np.ndarray:
    """Frames of stored MuJoCo states: physics_qpos (N, nq) of ``task`` -> (N, 3, H, W) uint8 from ``camera``.

    Each row is set on one env of the task (``set_physics_state``, velocities zero: a frame depends on
    positions alone) and drawn the way that env's "pixels" observations are, so a policy trained on
    these frames sees at evaluation exactly what it saw in training.
    """
    qpos = np.asarray(physics_qpos, dtype=np.float64)
    env = AlohaEnv(task=task, obs_type="pixels", render_size=size, camera=camera)
    try:
        if qpos.ndim != 2 or qpos.shape[1] != env.model.nq:
            raise ValueError(f"physics_qpos of {task!r} must be (N, {env.model.nq}); got shape {qpos.shape}")
        frames = np.empty((len(qpos), 3, *env.render_size), dtype=np.uint8)  # (N, 3, H, W)
        for i, q in enumerate(qpos):
            env.set_physics_state(q)
            frames[i] = env.render_camera(camera).transpose(2, 0, 1)  # (H, W, 3) -> (3, H, W)
        return frames
    finally:
        env.close()
