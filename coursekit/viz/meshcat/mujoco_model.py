"""Any MuJoCo model in meshcat: geoms converted once, poses streamed from ``mjData``, rollouts as HTML.

How it maps (MuJoCo and meshcat are both z-up, metres):

- Each drawn geom gets a meshcat node ``<root>/geoms/<id>_<name>`` whose transform is the geom's
  world pose (``data.geom_xpos`` (ngeom, 3), ``data.geom_xmat`` (ngeom, 9)); under it a ``shape``
  child carries the geometry, with a fixed offset where the two libraries' conventions differ.
- Geometry from ``model.geom_size`` (MuJoCo sizes are HALF extents and radii):

      box        Box(2 * size)
      sphere     Sphere(size[0])
      capsule    a triangle mesh built here (meshcat has no capsule): radius size[0], half-length size[1] along z
      cylinder   Cylinder(2 * size[1], size[0]) turned from meshcat's y axis to MuJoCo's z axis
      ellipsoid  Ellipsoid(size)
      plane      a thin box 2 * size[0] x 2 * size[1] just below z = 0 (size 0 = infinite: drawn 2 * extent wide)
      mesh       the compiled mesh's vertices and faces (already in the geom's frame)
      hfield, sdf: not drawn (listed in ``skipped``)

- Colour: ``geom_rgba``, except that MuJoCo lets a material's rgba win while the geom keeps the
  default rgba (0.5, 0.5, 0.5, 1); alpha < 1 is drawn transparent, alpha 0 not at all.
- Only geoms in ``groups`` are drawn (MuJoCo's viewer shows groups 0-2 by default; collision-only
  geoms usually sit in group 3).
- The whole model hangs under ``<root>``, shifted so that the moving geoms (arms, objects: what a
  rollout is about) sit on the origin the camera orbits, and the camera frames their bounding box.

A rollout becomes a meshcat animation: one keyframe per recorded step for every geom that moves
(static geoms keep their one transform), then :meth:`MujocoMeshcat.save_html` writes one
self-contained HTML file.
"""

from __future__ import annotations

import os

# This module draws nothing with MuJoCo, but it may be the first to import it: set the offscreen
# backend the course's camera rendering needs BEFORE mujoco loads (it is read at import time).
os.environ.setdefault("MUJOCO_GL", "egl")

import re  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from pathlib import Path  # noqa: E402

import meshcat.geometry as g  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from meshcat.animation import Animation, AnimationClip, AnimationTrack  # noqa: E402

from coursekit.tasks.aloha import CONTROL_HZ  # noqa: E402
from coursekit.viz.meshcat.scene import MeshcatScene, pose_matrix, rgb_hex, shared_scene, translation  # noqa: E402

_T = mujoco.mjtGeom
DEFAULT_RGBA = (0.5, 0.5, 0.5, 1.0)
"""MuJoCo's default geom rgba: a geom that keeps it shows its material's colour instead."""
PLANE_THICKNESS = 0.002
"""Thickness (m) of the box that stands in for a plane."""


# A tiny model with one geom of every type the bridge draws, each in its own colour, on a free body
# (so all of them move), plus a group-3 (collision-only) geom and an alpha-0 geom that are NOT
# drawn. Try it: ``MujocoMeshcat(mujoco.MjModel.from_xml_string(GEOM_GALLERY_XML))``.
GEOM_GALLERY_XML = """
<mujoco>
  <asset>
    <mesh name="tet" vertex="0 0 0  0.12 0 0  0 0.12 0  0 0 0.12"/>
    <material name="cyan" rgba="0 1 1 1"/>
  </asset>
  <worldbody>
    <light pos="0 0 3"/>
    <geom name="floor" type="plane" size="0.6 0.6 0.1" rgba="0.9 0.9 0.9 1"/>
    <body name="thing" pos="0 0 0.3">
      <freejoint/>
      <geom name="box" type="box" size="0.08 0.05 0.03" rgba="1 0 0 1"/>
      <geom name="sphere" type="sphere" size="0.06" pos="0.22 0 0" rgba="0 1 0 1"/>
      <geom name="capsule" type="capsule" size="0.035 0.07" pos="-0.22 0 0" rgba="0 0 1 1"/>
      <geom name="cylinder" type="cylinder" size="0.05 0.05" pos="0 0.22 0" rgba="1 1 0 1"/>
      <geom name="ellipsoid" type="ellipsoid" size="0.08 0.05 0.04" pos="0 -0.22 0" rgba="1 0 1 1"/>
      <geom name="mesh" type="mesh" mesh="tet" pos="0.15 0.15 0" material="cyan"/>
    </body>
    <geom name="collision_only" type="box" size="0.1 0.1 0.1" group="3"/>
    <geom name="invisible" type="sphere" size="0.1" rgba="0 0 0 0"/>
  </worldbody>
</mujoco>
"""
"""One geom of every drawable type (see the comment above)."""

def capsule_mesh(radius: float, half_length: float, n_around: int = 24, n_cap: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """A closed capsule along z, centred on the origin: vertices (N, 3), triangles (M, 3) wound outwards.

    Rings run from the top pole to the bottom pole: ``n_cap`` latitude rings on each hemisphere
    (the equator ring appears twice, at z = +half_length and -half_length; the band between the
    two is the cylinder), then a fan to each pole.
    """
    if not (radius > 0 and half_length >= 0):
        raise ValueError(f"capsule needs radius > 0 and half_length >= 0, got {radius}, {half_length}")
    theta = 2 * np.pi * np.arange(n_around) / n_around  # (n_around,)
    # latitudes of the top rings (from near the pole down to the equator), then the bottom rings
    top = np.linspace(np.pi / 2, 0.0, n_cap + 1)[1:]  # (n_cap,), excludes the pole
    lats = np.concatenate([top, -top[::-1]])  # (2 n_cap,)
    z_shift = np.where(np.arange(2 * n_cap) < n_cap, half_length, -half_length)  # (2 n_cap,)
    ring_r = radius * np.cos(lats)[:, None]  # (R, 1)
    ring_z = (radius * np.sin(lats) + z_shift)[:, None] * np.ones(n_around)  # (R, n_around)
    rings = np.stack([ring_r * np.cos(theta), ring_r * np.sin(theta), ring_z], axis=-1)  # (R, n_around, 3)
    n_rings = len(lats)
    verts = np.concatenate([[[0.0, 0.0, half_length + radius]], rings.reshape(-1, 3),
                            [[0.0, 0.0, -half_length - radius]]])  # (2 + R * n_around, 3)
    top_pole, bottom_pole = 0, len(verts) - 1

    def vid(ring: int, j: np.ndarray) -> np.ndarray:
        return 1 + ring * n_around + (j % n_around)

    j = np.arange(n_around)
    faces = [np.stack([np.full(n_around, top_pole), vid(0, j), vid(0, j + 1)], axis=1)]
    for k in range(n_rings - 1):  # quad (a upper j, b upper j+1, c lower j+1, d lower j) -> (a, d, c), (a, c, b)
        a, b, c, d = vid(k, j), vid(k, j + 1), vid(k + 1, j + 1), vid(k + 1, j)
        faces += [np.stack([a, d, c], axis=1), np.stack([a, c, b], axis=1)]
    faces.append(np.stack([np.full(n_around, bottom_pole), vid(n_rings - 1, j + 1), vid(n_rings - 1, j)], axis=1))
    return verts, np.concatenate(faces)  # (N, 3), (M, 3)


def geom_rgba(model: mujoco.MjModel, geom_id: int) -> np.ndarray:
    """The colour MuJoCo draws geom ``geom_id`` with: its rgba, or its material's when it kept the default."""
    rgba = np.array(model.geom_rgba[geom_id], dtype=np.float64)
    mat = int(model.geom_matid[geom_id])
    if mat >= 0 and np.allclose(rgba, DEFAULT_RGBA):
        rgba = np.array(model.mat_rgba[mat], dtype=np.float64)
    return rgba  # (4,)


def _safe(name: str) -> str:
    """A meshcat path element: no slashes (they would nest), nothing exotic."""
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name)


class MujocoMeshcat:
    """A MuJoCo model drawn in meshcat: :meth:`show` a state, or record a rollout as an animation.

    >>> viewer = MujocoMeshcat(env.model)                     # doctest: +SKIP
    >>> viewer.animate_qpos(qpos_trajectory, fps=50)          # (T, nq) joint positions
    >>> viewer.save_html("outputs/aloha_rollout.html")

    Args:
        model: the compiled ``mujoco.MjModel``.
        scene: the :class:`MeshcatScene` to draw in (default: the process's shared one); cleared.
        groups: geom groups to draw (MuJoCo's viewer default: 0, 1, 2).
        root: meshcat path of the model.
        camera: (elevation_deg, azimuth_deg) of the first view, looking at ``model.stat.center``.

    Attributes:
        geom_ids: (G,) ids of the drawn geoms. moving_ids: the subset that can move (their body
        is not welded to the world, or is a mocap body). skipped: names of geoms not drawn
        because of their type (hfield, sdf).
    """

    def __init__(self, model: mujoco.MjModel, scene: MeshcatScene | None = None, groups: Sequence[int] = (0, 1, 2),
                 root: str = "mujoco", camera: tuple[float, float] = (30.0, -90.0)) -> None:
        if not isinstance(model, mujoco.MjModel):
            raise ValueError(f"model must be a mujoco.MjModel, got {type(model).__name__}")
        self.model = model
        self.scene = shared_scene() if scene is None else scene
        self.root = _safe(root)
        self.groups = tuple(int(x) for x in groups)
        self.camera = camera
        self.skipped: list[str] = []
        self._scratch = mujoco.MjData(model)  # for forward kinematics of recorded qpos
        self._paths: dict[int, str] = {}
        self._build()

    # -- conversion (once) -------------------------------------------------------------------------
    def _geometry(self, geom_id: int) -> tuple[g.Geometry, np.ndarray] | None:
        """meshcat geometry of one geom and the offset (4, 4) of the shape in the geom frame."""
        m = self.model
        kind, size = int(m.geom_type[geom_id]), np.array(m.geom_size[geom_id], dtype=np.float64)
        eye = np.eye(4)
        if kind == _T.mjGEOM_BOX:
            return g.Box((2 * size).tolist()), eye
        if kind == _T.mjGEOM_SPHERE:
            return g.Sphere(float(size[0])), eye
        if kind == _T.mjGEOM_CAPSULE:
            verts, faces = capsule_mesh(float(size[0]), float(size[1]))
            return g.TriangularMeshGeometry(verts, faces), eye
        if kind == _T.mjGEOM_CYLINDER:
            y_to_z = pose_matrix([0, 0, 0], [[1, 0, 0], [0, 0, -1], [0, 1, 0]])  # meshcat's axis y -> z
            return g.Cylinder(float(2 * size[1]), float(size[0])), y_to_z
        if kind == _T.mjGEOM_ELLIPSOID:
            return g.Ellipsoid(size[:3].tolist()), eye
        if kind == _T.mjGEOM_PLANE:
            half = [s if s > 0 else 2 * m.stat.extent for s in size[:2]]  # size 0 = infinite
            return g.Box([2 * half[0], 2 * half[1], PLANE_THICKNESS]), translation([0, 0, -PLANE_THICKNESS / 2])
        if kind == _T.mjGEOM_MESH:
            mesh = int(m.geom_dataid[geom_id])
            v0, nv = int(m.mesh_vertadr[mesh]), int(m.mesh_vertnum[mesh])
            f0, nf = int(m.mesh_faceadr[mesh]), int(m.mesh_facenum[mesh])
            verts = np.array(m.mesh_vert[v0:v0 + nv], dtype=np.float64)  # (nv, 3) in the geom frame
            faces = np.array(m.mesh_face[f0:f0 + nf], dtype=np.int64)  # (nf, 3) indices into this mesh
            return g.TriangularMeshGeometry(verts, faces), eye
        return None  # hfield, sdf, ...

    def _build(self) -> None:
        m, scene = self.model, self.scene
        scene.clear()
        scene.hide_grid_and_axes()
        scene.set_background([0.93, 0.95, 0.97], [0.78, 0.82, 0.87])
        top = scene.vis[self.root]
        data = self._scratch
        mujoco.mj_forward(m, data)  # qpos0: every geom at its rest pose
        drawn, moving = [], []
        for i in range(m.ngeom):
            rgba = geom_rgba(m, i)
            if int(m.geom_group[i]) not in self.groups or rgba[3] <= 0:
                continue
            converted = self._geometry(i)
            name = m.geom(i).name or f"{m.body(int(m.geom_bodyid[i])).name or 'world'}_geom"
            if converted is None:
                self.skipped.append(name)
                continue
            geometry, offset = converted
            material = g.MeshLambertMaterial(color=rgb_hex(rgba[:3]), opacity=float(rgba[3]),
                                             transparent=bool(rgba[3] < 1.0))
            path = f"geoms/{i:03d}_{_safe(name)}"
            top[path]["shape"].set_object(geometry, material)
            top[path]["shape"].set_transform(offset)
            top[path].set_transform(pose_matrix(data.geom_xpos[i], data.geom_xmat[i]))
            self._paths[i] = path
            drawn.append(i)
            body = int(m.geom_bodyid[i])
            weld = int(m.body_weldid[body])
            if weld != 0 or int(m.body_mocapid[body]) >= 0:
                moving.append(i)
        self.geom_ids = np.array(drawn, dtype=int)
        self.moving_ids = np.array(moving, dtype=int)
        centre, radius = self.view_sphere(data)
        top.set_transform(translation(-centre))  # the camera orbits the origin
        elevation, azimuth = self.camera
        scene.frame(radius=radius, elevation_deg=elevation, azimuth_deg=azimuth)

    def view_sphere(self, data: mujoco.MjData) -> tuple[np.ndarray, float]:
        """Centre (3,) and radius of the part worth looking at: the moving geoms' bounding box.

        The moving geoms (arms, objects) are what a rollout is about; a model's own
        ``stat.center``/``stat.extent`` also take in floors and table legs and leave the action
        small in the middle. A model with nothing moving falls back to ``stat``.
        """
        ids = self.moving_ids if len(self.moving_ids) else np.array([], dtype=int)
        if len(ids) == 0:
            return np.asarray(self.model.stat.center, dtype=np.float64), 0.5 * float(self.model.stat.extent)
        pos, pad = data.geom_xpos[ids], self.model.geom_rbound[ids][:, None]  # (G, 3), (G, 1)
        lo, hi = (pos - pad).min(axis=0), (pos + pad).max(axis=0)  # (3,), (3,)
        # the box's circumscribed sphere frames it loosely (a corner is rarely at the silhouette's
        # edge from an oblique view); 0.75 of it fills the window without cutting the arms off
        return (lo + hi) / 2, max(0.75 * float(np.linalg.norm(hi - lo)) / 2, 1e-3)

    # -- poses ---------------------------------------------------------------------------------
    def show(self, data: mujoco.MjData) -> None:
        """Stream one frame: move every moving geom to its pose in ``data``.

        ``mj_step`` computes positions BEFORE it integrates, so right after a step ``geom_xpos``
        lags ``qpos`` by one physics step; call ``mujoco.mj_kinematics`` (or ``mj_forward``) first
        when the exact current pose matters.
        """
        top = self.scene.vis[self.root]
        for i in self.moving_ids:
            top[self._paths[i]].set_transform(pose_matrix(data.geom_xpos[i], data.geom_xmat[i]))

    def poses_from_qpos(self, qpos) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics of a trajectory: qpos (T, nq) -> geom_xpos (T, ngeom, 3), geom_xmat (T, ngeom, 9)."""
        q = np.asarray(qpos, dtype=np.float64)
        if q.ndim != 2 or q.shape[1] != self.model.nq or len(q) == 0 or not np.all(np.isfinite(q)):
            raise ValueError(f"qpos must be finite with shape (T, {self.model.nq}), T >= 1; got shape {q.shape}")
        data = self._scratch
        xpos = np.empty((len(q), self.model.ngeom, 3))
        xmat = np.empty((len(q), self.model.ngeom, 9))
        for t, row in enumerate(q):
            data.qpos[:] = row
            mujoco.mj_kinematics(self.model, data)  # positions only: no dynamics needed to draw
            xpos[t], xmat[t] = data.geom_xpos, data.geom_xmat
        return xpos, xmat

    def animate(self, geom_xpos, geom_xmat, fps: float = CONTROL_HZ, play: bool = True, repetitions: int = 1) -> Animation:
        """Record a rollout from per-step geom poses and load it in the scene as an animation.

        Args:
            geom_xpos: (T, ngeom, 3) stacked copies of ``data.geom_xpos`` (see :meth:`show` on
                their one-physics-step lag after ``mj_step``).
            geom_xmat: (T, ngeom, 9) stacked copies of ``data.geom_xmat``.
            fps: playback rate (ALOHA's control rate is 50 Hz; pass a stride-adjusted rate if you
                keep every k-th step).
            play: start playing when the page opens (False: the page shows the first step).
            repetitions: how many times the animation plays.

        Only geoms that actually move get keyframes, which keeps the HTML small. The static
        scene is set to the first step, so the page shows it before (and without) playing.
        """
        xpos = np.asarray(geom_xpos, dtype=np.float64)
        xmat = np.asarray(geom_xmat, dtype=np.float64)
        ng = self.model.ngeom
        if xpos.ndim != 3 or xpos.shape[1:] != (ng, 3) or len(xpos) == 0:
            raise ValueError(f"geom_xpos must have shape (T, {ng}, 3) with T >= 1, got {xpos.shape}")
        if xmat.shape != (len(xpos), ng, 9):
            raise ValueError(f"geom_xmat must have shape ({len(xpos)}, {ng}, 9) to match geom_xpos, got {xmat.shape}")
        if not (np.all(np.isfinite(xpos)) and np.all(np.isfinite(xmat))):
            raise ValueError("geom poses must be finite (a NaN state cannot be drawn)")
        if not fps > 0:
            raise ValueError(f"fps must be positive, got {fps}")
        if repetitions < 1:
            raise ValueError(f"repetitions must be >= 1, got {repetitions}")
        top = self.scene.vis[self.root]
        anim = Animation(default_framerate=fps)
        frames = list(range(len(xpos)))
        quat = np.empty(4)
        for i in self.geom_ids:
            top[self._paths[i]].set_transform(pose_matrix(xpos[0, i], xmat[0, i]))
            still = np.ptp(xpos[:, i], axis=0).max() < 1e-9 and np.ptp(xmat[:, i], axis=0).max() < 1e-9
            if still:
                continue
            quats = []
            for mat in xmat[:, i]:
                mujoco.mju_mat2Quat(quat, mat)
                quats.append([quat[1], quat[2], quat[3], quat[0]])  # MuJoCo (w, x, y, z) -> three.js (x, y, z, w)
            clip = AnimationClip(fps=fps, tracks={
                "position": AnimationTrack("position", "vector3", frames, xpos[:, i].tolist()),
                "quaternion": AnimationTrack("quaternion", "quaternion", frames, quats),
            })
            anim.clips[top[self._paths[i]].path] = clip
        self.scene.vis.set_animation(anim, play=play, repetitions=repetitions)
        return anim

    def animate_qpos(self, qpos, fps: float = CONTROL_HZ, play: bool = True, repetitions: int = 1) -> Animation:
        """Record a rollout from joint positions qpos (T, nq) (forward kinematics per step)."""
        xpos, xmat = self.poses_from_qpos(qpos)
        return self.animate(xpos, xmat, fps=fps, play=play, repetitions=repetitions)

    # -- export --------------------------------------------------------------------------------
    def html(self) -> str:
        """The scene (and its animation) as one self-contained HTML page."""
        return self.scene.static_html()

    def save_html(self, path: str | os.PathLike) -> Path:
        """Write :meth:`html` to ``path`` atomically; return the path."""
        return self.scene.save_html(path)


def export_mujoco_rollout(model: mujoco.MjModel, qpos, path: str | os.PathLike, fps: float = CONTROL_HZ, play: bool = True,
                          scene: MeshcatScene | None = None) -> Path:
    """One call: draw ``model``, record the joint trajectory ``qpos`` (T, nq) and write the HTML."""
    viewer = MujocoMeshcat(model, scene)
    viewer.animate_qpos(qpos, fps=fps, play=play)
    return viewer.save_html(path)
