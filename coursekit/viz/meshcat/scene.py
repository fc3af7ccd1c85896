"""One meshcat scene per process, owned, framed for the camera and closed cleanly.

A :class:`MeshcatScene` is a ``meshcat.Visualizer`` connected to its own server process
(:class:`coursekit.viz.meshcat.server.MeshcatServer`: listening on 127.0.0.1 only, and dying
with this process however it dies). :meth:`MeshcatScene.close` kills the server; it is also
registered with ``atexit`` and run by ``with``. :func:`shared_scene` hands out one scene per
process, which the course's viewers share.

Everything the course shows is exported with :meth:`MeshcatScene.static_html`: one self-contained
HTML file (about 0.9 MB; three.js is inlined) with the scene and its animation, which works
offline and outlives the server. Notebooks never embed the live server.

Coordinates: meshcat is z-up (world). Its default camera lives at ``/Cameras/default/rotated``
(rotated so that three.js's y-up is world z-up) and orbits the world origin, so each scene centres
its content on the origin and :meth:`MeshcatScene.set_camera` places the camera in world
coordinates.
"""

from __future__ import annotations

import atexit
import contextlib
import io
import os
from collections.abc import Sequence
from pathlib import Path
from typing import ClassVar

import meshcat
import numpy as np
import zmq

from coursekit.atomic import atomic_write_text
from coursekit.viz.meshcat.server import MeshcatServer

# The camera object meshcat's viewer creates at start-up (see meshcat's viewer ``create_camera``).
CAMERA_PATH = "/Cameras/default/rotated/<object>"
# Milliseconds to wait for the server's reply to one command (static_html of a big scene included).
_REPLY_TIMEOUT_MS = 60_000


def translation(xyz: Sequence[float]) -> np.ndarray:
    """(4, 4) homogeneous transform that translates by ``xyz`` (3,)."""
    tf = np.eye(4)
    tf[:3, 3] = np.asarray(xyz, dtype=float)
    return tf


def pose_matrix(position: Sequence[float], rotation: np.ndarray) -> np.ndarray:
    """(4, 4) homogeneous transform from a position (3,) and a rotation matrix (3, 3)."""
    tf = np.eye(4)
    tf[:3, :3] = np.asarray(rotation, dtype=float).reshape(3, 3)  # (3, 3)
    tf[:3, 3] = np.asarray(position, dtype=float)
    return tf


def rgb_hex(rgb: Sequence[float]) -> int:
    """Colour as meshcat wants it (0xRRGGBB int) from r, g, b in [0, 1]."""
    r, g, b = (int(round(255 * float(np.clip(c, 0.0, 1.0)))) for c in rgb[:3])
    return (r << 16) | (g << 8) | b


class MeshcatScene:
    """One meshcat Visualizer and the server process behind it; use ``with`` or call :meth:`close`.

    >>> with MeshcatScene() as scene:          # doctest: +SKIP
    ...     scene.vis["box"].set_object(meshcat.geometry.Box([1, 1, 1]))
    ...     scene.save_html("box.html")

    Attributes:
        vis: the root ``meshcat.Visualizer``; index it (``vis["pusht/block"]``) to make objects.
        server_pid: process id of the server subprocess (to check that it is gone after close).
        web_url: the live server's URL (only useful while the process lives; prefer the HTML).
    """

    _shared: ClassVar[MeshcatScene | None] = None
    """The scene handed out by :func:`shared_scene` (one server per process)."""

    def __init__(self) -> None:
        self._server = MeshcatServer()
        self.server_pid: int = self._server.pid
        self.web_url: str = self._server.web_url
        atexit.register(self.close)
        try:
            # Visualizer(zmq_url=...) connects to our server instead of starting its own; it
            # prints the URL on stdout, which would only clutter notebooks and test logs.
            with contextlib.redirect_stdout(io.StringIO()):
                self.vis = meshcat.Visualizer(zmq_url=self._server.zmq_url)
            # meshcat waits for every reply without a limit: a dead server would hang the caller
            # forever. With a timeout it raises zmq.Again instead (and the scene must be remade).
            self.vis.window.zmq_socket.setsockopt(zmq.RCVTIMEO, _REPLY_TIMEOUT_MS)
            self.vis.window.zmq_socket.setsockopt(zmq.SNDTIMEO, _REPLY_TIMEOUT_MS)
        except BaseException:
            self.close()
            raise

    # -- lifetime -----------------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        """True once :meth:`close` ran (the server is dead and the Visualizer unusable)."""
        return self._server.closed

    def close(self) -> None:
        """Close the zmq socket and kill the server process. Safe to call twice."""
        if self._server.closed:
            return
        atexit.unregister(self.close)
        window = getattr(getattr(self, "vis", None), "window", None)
        if window is not None:
            window.zmq_socket.close(linger=0)
        self._server.close()

    def __enter__(self) -> MeshcatScene:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def _check_open(self) -> None:
        if self.closed:
            raise RuntimeError("this MeshcatScene is closed (its server was killed); make a new one")

    # -- scene housekeeping ----------------------------------------------------------------------
    def clear(self) -> None:
        """Delete every object, transform, property and animation (a blank scene, same server)."""
        self._check_open()
        self.vis.delete()

    def set_background(self, top_rgb: Sequence[float], bottom_rgb: Sequence[float] | None = None) -> None:
        """Background gradient colours, r, g, b in [0, 1] (bottom defaults to top: a flat colour)."""
        self._check_open()
        bottom_rgb = top_rgb if bottom_rgb is None else bottom_rgb
        self.vis["/Background"].set_property("top_color", [float(c) for c in top_rgb[:3]])
        self.vis["/Background"].set_property("bottom_color", [float(c) for c in bottom_rgb[:3]])

    def hide_grid_and_axes(self) -> None:
        """Hide meshcat's default 20 m grid and axes triad (they dwarf a table-top scene)."""
        self._check_open()
        self.vis["/Grid"].set_property("visible", False)
        self.vis["/Axes"].set_property("visible", False)

    def set_camera(self, position: Sequence[float]) -> None:
        """Place the default camera at world ``position`` (3,), z up, looking at the origin.

        The camera node is rotated +90 deg about x (three.js is y-up), so world (x, y, z) is
        (x, z, -y) in the camera's parent frame. The orbit controls keep looking at the origin.
        """
        self._check_open()
        x, y, z = (float(v) for v in position)
        if not np.isfinite([x, y, z]).all() or (x, y, z) == (0.0, 0.0, 0.0):
            raise ValueError(f"camera position must be finite and not the origin, got {tuple(position)}")
        self.vis[CAMERA_PATH].set_property("position", [x, z, -y])

    def frame(self, radius: float, elevation_deg: float = 60.0, azimuth_deg: float = -90.0, fov_deg: float = 75.0,
              margin: float = 1.1) -> None:
        """Aim the camera at the origin so that a sphere of ``radius`` (m) fills the view.

        The distance is radius * margin / sin(fov / 2): the sphere just fits the vertical field
        of view of meshcat's default perspective camera (75 deg), which is the tighter one in a
        landscape window. ``azimuth_deg`` -90 puts the camera on the -y side looking towards +y,
        so world +y points up the screen (like a top-down image).
        """
        if not radius > 0 or not np.isfinite(radius):
            raise ValueError(f"radius must be a positive finite number, got {radius}")
        if not 0 < elevation_deg <= 90:
            raise ValueError(f"elevation_deg must be in (0, 90], got {elevation_deg}")
        distance = radius * margin / np.sin(np.radians(fov_deg) / 2)
        el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
        # at 90 deg elevation the orbit controls' up vector (z) is degenerate; tilt a hair
        el = min(el, np.radians(89.0))
        self.set_camera(distance * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]))

    # -- export ----------------------------------------------------------------------------------
    def static_html(self) -> str:
        """The whole scene (objects, properties, animation) as one self-contained HTML page."""
        self._check_open()
        return self.vis.static_html()

    def save_html(self, path: str | os.PathLike) -> Path:
        """Write :meth:`static_html` to ``path`` atomically; return the path."""
        path = Path(path)
        atomic_write_text(path, self.static_html())
        return path


def shared_scene() -> MeshcatScene:
    """The process's one :class:`MeshcatScene`, started on first use and restarted if closed.

    A meshcat server is a per-process resource (a subprocess holding two ports), so the course's
    viewers share one instead of each starting its own. ``MeshcatScene._shared`` is the one
    deliberate piece of process-wide state in the viz package; ``atexit`` closes what it holds.
    """
    scene = MeshcatScene._shared
    if scene is None or scene.closed:
        scene = MeshcatScene._shared = MeshcatScene()
    return scene
