"""The replay's viewers: how each simulator's world is drawn, for any task that lives in it.

A task's record names its viewer (``coursekit.tasks.ReplayDrawing.viewer``); :mod:`coursekit.viz.replay`
asks it to check the recorded states, animate them in a meshcat scene and render the first and
last frame of each episode:

    pusht    the planar PushT scene (``PushTMeshcat``) and PushT's own renderer (``PushTRenderer``);
             states (T + 1, 5) [agent x, y, block x, y, angle] or (T + 1, 7) as ``PushTEnv.get_state()``
    mujoco   the task env's MuJoCo model (``MujocoMeshcat``) and its ``drawing.camera``, through the
             env's ``set_physics_state`` / ``render_camera`` (the arm pair); states (T + 1, nq) qpos

A new task in one of these worlds needs no code here.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from coursekit.tasks.record import Task

if TYPE_CHECKING:
    from coursekit.viz.meshcat.scene import MeshcatScene


class PushTViewer:
    """PushT's world: the planar meshcat scene and the env's own renderer."""

    def __init__(self, task: Task) -> None:
        self.task = task
        self.panel_hw = task.replay.panel_hw

    def check(self, i: int, seed: int, states: np.ndarray) -> None:
        """Refuse states that are not PushT states (ValueError naming the episode)."""
        if states.shape[1] not in (5, 7):
            raise ValueError(f"episodes[{i}] (seed {seed}): PushT states must have shape (T + 1, 5) [ax, ay, bx, "
                             f"by, angle] or (T + 1, 7) (PushTEnv.get_state()), got {states.shape}")

    def animate(self, scene: MeshcatScene, states: np.ndarray, fps: float) -> None:
        """Key every state (F, S) into ``scene``'s animation at ``fps``."""
        from coursekit.viz.meshcat.pusht import PushTMeshcat

        PushTMeshcat(scene, show_target=False).animate(states[:, :5], fps=fps, play=True)

    def frames(self, states: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
        """(first, last) (H, W, 3) uint8 images of each episode's states."""
        from coursekit.envs.pusht_render import PushTRenderer

        renderer = PushTRenderer(self.panel_hw)
        return [(renderer.render(s[0, :5]), renderer.render(s[-1, :5])) for s in states]

    def close(self) -> None:
        pass


class MujocoViewer:
    """A MuJoCo task's world: the env's model in meshcat, frames from one of the env's cameras."""

    def __init__(self, task: Task) -> None:
        self.task = task
        self.panel_hw = task.replay.panel_hw
        self.env: Any = task.make_env()
        self.model = self.env.unwrapped.model

    def check(self, i: int, seed: int, states: np.ndarray) -> None:
        """Refuse states that are not this model's qpos (ValueError naming the episode)."""
        nq, width = self.model.nq, states.shape[1]
        if width != nq:
            start = self.task.replay.columns[0]
            hint = (f" (this looks like a recorded evaluation row of {self.task.name}: pass states[:, {start}:])"
                    if width == start + nq else "")
            raise ValueError(f"episodes[{i}] (seed {seed}): {self.task.name} states must be MuJoCo qpos of shape "
                             f"(T + 1, {nq}), got {states.shape}{hint}")

    def animate(self, scene: MeshcatScene, states: np.ndarray, fps: float) -> None:
        """Key every qpos (F, nq) into ``scene``'s animation at ``fps``."""
        from coursekit.viz.meshcat.mujoco_model import MujocoMeshcat

        MujocoMeshcat(self.model, scene).animate_qpos(states, fps=fps, play=True)

    def frames(self, states: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
        """(first, last) (H, W, 3) uint8 camera images of each episode's qpos."""
        out = []
        for s in states:
            pair = []
            for q in (s[0], s[-1]):
                self.env.unwrapped.set_physics_state(q)
                pair.append(self.env.unwrapped.render_camera(self.task.replay.camera, self.panel_hw).copy())
            out.append((pair[0], pair[1]))
        return out

    def close(self) -> None:
        self.env.close()


VIEWERS = {"pusht": PushTViewer, "mujoco": MujocoViewer}
"""``ReplayDrawing.viewer`` -> the viewer class (built from the task record)."""


def viewer_for(task: Task) -> PushTViewer | MujocoViewer:
    """The viewer that draws ``task``'s replays (ValueError if its record has no replay drawing)."""
    if task.replay is None:
        raise ValueError(f"task {task.name!r} has no replay drawing (its record's replay is None)")
    return VIEWERS[task.replay.viewer](task)
