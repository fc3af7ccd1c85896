"""What the policy did, for a person to look at: a meshcat HTML replay and a first/last-frame grid.

:func:`write_replay` turns recorded evaluation episodes into two files in ``out_dir``:

- ``replay.html``: ONE self-contained meshcat page (three.js inlined, works offline) that plays the
  episodes ONE AFTER ANOTHER on a single time line, each followed by a one-second hold on its
  final state, under a caption box that names the episode on screen (seed, score, success).
  Why a time line rather than side by side: every episode gets the whole window at the scale
  the course's viewers frame one scene at (side by side, five arm pairs would each be tiny);
  the scene holds one copy of the model (the viewers own one scene root each); the file size is
  the same either way (one keyframe per moving part per step); and meshcat's time slider gives
  direct access to any episode.
- ``frames.png``: a grid with one row per episode, its first and last frame drawn by the task's
  own renderer (:class:`coursekit.envs.pusht_render.PushTRenderer`, the arm pair's offscreen
  MuJoCo camera), each row captioned with seed, score and success.

What is drawn, and from which states, is the task's record's ``replay`` (``coursekit.tasks``): its
viewer (:mod:`coursekit.viz.replay_viewers`), the frame size and the playback rate (the task's
control rate). States are what a rollout records (``RecordAdapter.replay_states``):

    pusht                      (T + 1, 5) [agent x, agent y, block x, block y, block angle]
                               or (T + 1, 7) as ``PushTEnv.get_state()`` gives (+ agent vx, vy; ignored)
    transfer_cube, insertion   (T + 1, nq) MuJoCo qpos, ``AlohaEnv.get_physics_state()["physics_qpos"]``

Both files are built in memory first and written atomically, and neither replaces a file that
is already there (unless ``overwrite``): a failed call leaves ``out_dir`` as it was.
"""

from __future__ import annotations

import html
import io
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from coursekit.tasks.record import Task
from coursekit.tasks.registry import get_task
from coursekit.viz.replay_viewers import viewer_for

if TYPE_CHECKING:
    from coursekit.output_lock import OutputLock
    from coursekit.viz.meshcat.scene import MeshcatScene

HOLD_S = 1.0
"""Seconds the replay holds each episode's final state before the next one starts."""
MAX_EPISODES = 24
"""Most episodes in one replay (an arm-pair episode adds about 2 MB to the page)."""
REPLAY_NAME, FRAMES_NAME = "replay.html", "frames.png"
"""File names written in ``out_dir``."""
MARGIN, GAP, CAPTION_H, HEADER_H = 10, 8, 26, 24
"""frames.png layout in pixels: outer margin, gap between panels, row caption band, column-title band."""


@dataclass
class EpisodeRecording:
    """One evaluated episode, as much of it as a replay needs.

    Attributes:
        seed: the environment seed the episode was reset with.
        states: (T + 1, S) the simulator state before each of the T actions and after the last
            (see the module docstring for S per task).
        score: the episode's score (PushT: max coverage; arm pair: the highest stage reached or 1/0).
        success: whether the episode counts as a success.
        label: optional extra caption text (e.g. "DP DDIM-10").
    """

    seed: int
    states: np.ndarray
    score: float
    success: bool
    label: str = ""

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)):
            raise ValueError(f"seed must be an int, got {self.seed!r}")
        self.seed = int(self.seed)
        try:
            states = np.array(self.states, dtype=np.float64)  # a copy: later edits of the caller's array don't leak in
        except (TypeError, ValueError) as err:
            raise ValueError(f"episode seed {self.seed}: states must be a numeric (T + 1, S) array") from err
        if states.ndim != 2 or len(states) == 0:
            raise ValueError(f"episode seed {self.seed}: states must have shape (T + 1, S) with at least one "
                             f"row, got shape {states.shape}")
        if not np.all(np.isfinite(states)):
            t, col = np.argwhere(~np.isfinite(states))[0]
            raise ValueError(f"episode seed {self.seed}: states must be finite, got {states[t, col]} at step {t}, "
                             f"column {col}")
        self.states = states
        if isinstance(self.score, bool) or not isinstance(self.score, (int, float, np.integer, np.floating)) \
                or not math.isfinite(self.score):
            raise ValueError(f"episode seed {self.seed}: score must be a finite number, got {self.score!r}")
        self.score = float(self.score)
        if not isinstance(self.success, (bool, np.bool_)):
            raise ValueError(f"episode seed {self.seed}: success must be a bool, got {self.success!r}")
        self.success = bool(self.success)
        if not isinstance(self.label, str):
            raise ValueError(f"episode seed {self.seed}: label must be a str, got {self.label!r}")

    def caption(self) -> str:
        """One line: seed, score, success (and the label)."""
        text = f"seed {self.seed} | score {self.score:.3g} | {'success' if self.success else 'failure'}"
        return f"{text} | {self.label}" if self.label else text


# -- validation ------------------------------------------------------------------------------------
def _check_episodes(viewer: Any, episodes: Sequence[EpisodeRecording]) -> list[EpisodeRecording]:
    """The episodes as a list, each checked against the task's state layout (by its viewer)."""
    if isinstance(episodes, EpisodeRecording):
        raise ValueError("episodes must be a sequence of EpisodeRecording; got one EpisodeRecording (wrap it in a list)")
    episodes = list(episodes)
    if not 1 <= len(episodes) <= MAX_EPISODES:
        raise ValueError(f"a replay shows 1 to {MAX_EPISODES} episodes, got {len(episodes)}")
    for i, ep in enumerate(episodes):
        if not isinstance(ep, EpisodeRecording):
            raise ValueError(f"episodes[{i}] must be an EpisodeRecording, got {type(ep).__name__}")
        viewer.check(i, ep.seed, ep.states)
    return episodes


def _check_out_dir(out_dir: Path, overwrite: bool) -> tuple[Path, Path]:
    if out_dir.exists() and not out_dir.is_dir():
        raise NotADirectoryError(f"out_dir {out_dir} exists and is not a folder")
    targets = out_dir / REPLAY_NAME, out_dir / FRAMES_NAME
    if not overwrite:
        taken = [str(p) for p in targets if p.exists() or p.is_symlink()]
        if taken:
            raise FileExistsError(f"{' and '.join(taken)} already exist(s); choose another folder or pass overwrite=True")
    return targets


# -- the HTML replay ---------------------------------------------------------------------------------
def timeline(lengths: Sequence[int], fps: float, hold_s: float = HOLD_S) -> tuple[np.ndarray, int]:
    """Start frame (N,) of each episode on the shared time line and the hold (frames) after each.

    Episode i occupies frames ``start[i] .. start[i] + lengths[i] - 1``, then its last state is
    held for ``hold`` frames.
    """
    hold = max(1, int(round(hold_s * fps)))
    starts = np.concatenate([[0], np.cumsum(np.asarray(lengths) + hold)[:-1]]).astype(int)
    return starts, hold


def _played_states(episodes: list[EpisodeRecording], hold: int) -> np.ndarray:
    """All episodes' states one after another, each final state repeated ``hold`` times: (F, S)."""
    parts = []
    for ep in episodes:
        parts += [ep.states, np.repeat(ep.states[-1:], hold, axis=0)]
    return np.concatenate(parts)  # (sum(T_i + 1 + hold), S)


def _caption_overlay(task: str, episodes: list[EpisodeRecording], starts_s: list[float]) -> str:
    """A fixed caption box and a script that names the episode at the animation's current time.

    It reads ``viewer.animator.time`` (the time meshcat's slider shows; ``viewer`` is the global
    the exported page creates, as in the pinned meshcat 0.3.2). Without it the box still lists
    every episode and when it starts.
    """
    rows = "".join(
        f"<tr data-start='{s:.3f}'><td>{i + 1}.</td><td style='padding:0 8px'>{html.escape(ep.caption())}</td>"
        f"<td>from {s:.1f} s</td></tr>"
        for i, (ep, s) in enumerate(zip(episodes, starts_s)))
    title = f"{html.escape(task)}: " + (f"{len(episodes)} episodes, one after another" if len(episodes) > 1 else "1 episode")
    return f"""
<div id="coursekit-replay" style="position:fixed;top:8px;left:8px;z-index:10;max-width:60%;
 background:rgba(255,255,255,0.88);border-radius:4px;padding:6px 10px;font:13px sans-serif;color:#222">
 <div style="font-weight:bold">{title}</div>
 <div id="coursekit-now" style="font-size:16px;margin:4px 0">episode 1: {html.escape(episodes[0].caption())}</div>
 <table style="border-collapse:collapse;font-size:12px">{rows}</table>
</div>
<script>
(function () {{
  var rows = document.querySelectorAll("#coursekit-replay tr");
  var now = document.getElementById("coursekit-now");
  function update() {{
    var t = (typeof viewer !== "undefined" && viewer.animator) ? viewer.animator.time : 0, k = 0;
    for (var i = 0; i < rows.length; i++) {{ if (parseFloat(rows[i].dataset.start) <= t + 1e-6) k = i; }}
    for (var j = 0; j < rows.length; j++) rows[j].style.fontWeight = j === k ? "bold" : "normal";
    now.textContent = "episode " + (k + 1) + ": " + rows[k].cells[1].textContent;
    now.dataset.episode = String(k + 1);
    window.requestAnimationFrame(update);  // in step with meshcat's own drawing loop
  }}
  update();
}})();
</script>
"""


def replay_html(viewer: Any, episodes: list[EpisodeRecording], fps: float, scene: MeshcatScene | None = None) -> str:
    """The replay page as a string (see the module docstring), drawn by the task's ``viewer``."""
    from coursekit.viz.meshcat.scene import MeshcatScene

    starts, hold = timeline([len(ep.states) for ep in episodes], fps)
    states = _played_states(episodes, hold)  # (F, S)
    own = scene is None
    scene = MeshcatScene() if own else scene
    try:
        viewer.animate(scene, states, fps)
        page = scene.static_html()
    finally:
        if own:
            scene.close()
    overlay = _caption_overlay(viewer.task.name, episodes, [float(s) / fps for s in starts])
    cut = page.rfind("</body>")
    if cut < 0:
        raise RuntimeError("meshcat's static HTML has no </body>: cannot add the caption box")
    return page[:cut] + overlay + page[cut:]


# -- the first/last frame grid -------------------------------------------------------------------------
def _panel_hw(task: Task | str) -> tuple[int, int]:
    record = task if isinstance(task, Task) else get_task(task)
    if record.replay is None:
        raise ValueError(f"task {record.name!r} has no replay drawing (its record's replay is None)")
    return record.replay.panel_hw


def panel_origin(row: int, col: int, task: Task | str) -> tuple[int, int]:
    """(y, x) pixel of the top-left corner of frame ``col`` (0 first, 1 last) of row ``row`` in frames.png."""
    h, w = _panel_hw(task)
    return MARGIN + HEADER_H + row * (CAPTION_H + h + GAP) + CAPTION_H, MARGIN + col * (w + GAP)


def frames_grid(viewer: Any, episodes: list[EpisodeRecording]) -> np.ndarray:
    """The frames.png picture (H, W, 3) uint8: one row per episode, first and last frame (by ``viewer``), captioned."""
    from PIL import Image, ImageDraw, ImageFont

    task = viewer.task
    h, w = viewer.panel_hw
    n = len(episodes)
    width = 2 * MARGIN + 2 * w + GAP
    height = 2 * MARGIN + HEADER_H + n * (CAPTION_H + h + GAP) - GAP
    img = Image.new("RGB", (width, height), (255, 255, 255))
    draw = ImageDraw.Draw(img)
    font = ImageFont.load_default(size=14)
    draw.text((MARGIN, MARGIN + 2), "first frame", fill=(60, 60, 60), font=font)
    draw.text((MARGIN + w + GAP, MARGIN + 2), "last frame", fill=(60, 60, 60), font=font)
    for r, (ep, frames) in enumerate(zip(episodes, viewer.frames([e.states for e in episodes]))):
        y0, _ = panel_origin(r, 0, task)
        colour = (20, 120, 50) if ep.success else (180, 30, 30)
        steps = len(ep.states) - 1
        draw.text((MARGIN, y0 - CAPTION_H + 5), f"{r + 1}. {ep.caption()} | {steps} steps", fill=colour, font=font)
        for c, frame in enumerate(frames):
            y, x = panel_origin(r, c, task)
            img.paste(Image.fromarray(frame), (x, y))
    return np.asarray(img)  # (H, W, 3)


def _png_bytes(image: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="PNG")
    return buf.getvalue()


# -- the one call ----------------------------------------------------------------------------------------
def write_replay(out_dir: str | os.PathLike, task: Task | str, episodes: Sequence[EpisodeRecording], *,
                 fps: float | None = None, overwrite: bool = False,
                 scene: MeshcatScene | None = None, lock: OutputLock | None = None) -> dict[str, Path]:
    """Write ``replay.html`` and ``frames.png`` for ``episodes`` of ``task`` into ``out_dir``.

    Args:
        out_dir: folder for the two files (created if missing). Files already there with those
            names are refused (FileExistsError naming them) unless ``overwrite``.
        task: a task name ("pusht", "transfer_cube", "insertion", ...) or record whose ``replay`` says how to draw it.
        episodes: 1 to :data:`MAX_EPISODES` recordings, played in this order.
        fps: playback rate of the HTML (default: the task's control rate, its record's ``control_hz``).
        overwrite: replace existing ``replay.html`` / ``frames.png``.
        scene: a :class:`MeshcatScene` to draw in (cleared); default: a private one, closed after.
        lock: the caller's lock on ``out_dir`` (``coursekit eval --record`` holds one), under which
            both files are written; default: each file is locked while it is written.

    Returns:
        {"html": path of replay.html, "frames": path of frames.png}.

    Everything is checked, drawn and rendered before the first byte is written.
    """
    from coursekit.atomic import atomic_write_bytes, atomic_write_text

    record = task if isinstance(task, Task) else get_task(task)
    fps = record.control_hz if fps is None else fps
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not (math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive finite number, got {fps!r}")
    out_dir = Path(out_dir)
    html_path, png_path = _check_out_dir(out_dir, overwrite)
    viewer = viewer_for(record)
    try:
        episodes = _check_episodes(viewer, episodes)
        page = replay_html(viewer, episodes, float(fps), scene=scene)
        png = _png_bytes(frames_grid(viewer, episodes))
    finally:
        viewer.close()
    out_dir.mkdir(parents=True, exist_ok=True)
    _check_out_dir(out_dir, overwrite)  # again: nothing appeared while we drew
    atomic_write_text(html_path, page, lock=lock)
    atomic_write_bytes(png_path, png, lock=lock)
    return {"html": html_path, "frames": png_path}

