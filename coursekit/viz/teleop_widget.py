"""Push the T yourself: a JupyterLab widget that records PushT demonstrations with the mouse.

Why anywidget: one small PyPI package whose prebuilt JupyterLab extension runs a few dozen lines
of plain JavaScript (below, no build step, no npm) next to a Python object with synced traits.
The browser only draws on a ``<canvas>`` and reports the mouse; the world itself steps in
Python, in a real ``PushTEnv``, through :class:`coursekit.teleop.TeleopRecorder`, so a
recording is exactly what the recorder would produce from the same targets.

Timing: while recording, the page sends one "tick" with the current mouse target every
1 / ``PUSHT.control_hz`` s (the env's control rate) and waits for Python's answer before the next one, so the
world never runs ahead of the kernel: each tick is one control step. Ticks begin at the first
press on the canvas after Start, so no idle steps are recorded while you reach for the mouse.

Controls: Start (reset: the next seed, or the fixed start), drag the blue pusher, Stop (keep
the episode; written to ``path`` at once when given), Discard (drop it). An episode also stops
by itself a few steps after success, or after ``max_steps``. The readout shows the coverage.
"""

from __future__ import annotations

import anywidget
import numpy as np
import traitlets

from coursekit.envs import pusht_geometry as geo
from coursekit.envs.pusht_render import AGENT_COLOR, BLOCK_COLOR, GOAL_COLOR, TARGET_COLOR
from coursekit.tasks.pusht import PUSHT
from coursekit.teleop import TeleopRecorder

_ESM = r"""
function rgb(c) { return `rgb(${c[0]},${c[1]},${c[2]})`; }

function render({ model, el }) {
  const size = model.get("size");
  const k = size / 512;
  const root = document.createElement("div");
  root.className = "ck-teleop";
  root.style.cssText = "display:inline-flex;flex-direction:column;gap:6px;font:13px sans-serif";
  const canvas = document.createElement("canvas");
  canvas.width = size; canvas.height = size;
  canvas.className = "ck-teleop-canvas";
  // Shown at `size` px, not stretched to the button bar's width (a column flex box stretches its
  // items); only a narrower output area shrinks it, keeping it square.
  canvas.style.cssText = `width:${size}px;max-width:100%;height:auto;flex:none;align-self:flex-start;` +
    "box-sizing:content-box;border:1px solid #999;cursor:crosshair;touch-action:none";
  const bar = document.createElement("div");
  bar.style.cssText = "display:flex;gap:6px;align-items:center";
  const mk = (label, cls) => { const b = document.createElement("button"); b.textContent = label;
    b.className = "ck-teleop-" + cls; bar.appendChild(b); return b; };
  const start = mk("Start", "start"), stop = mk("Stop (keep)", "stop"), discard = mk("Discard", "discard");
  const readout = document.createElement("span");
  readout.className = "ck-teleop-readout";
  bar.appendChild(readout);
  root.append(canvas, bar);
  el.appendChild(root);

  // starting: Start was clicked and Python has not yet answered "recording": a drag that begins
  // in that moment counts (a busy kernel would otherwise swallow it and nothing is recorded)
  let target = null, dragging = false, touched = false, pending = false, starting = false;
  const ctx = canvas.getContext("2d");
  const poly = (pts, fill, stroke) => { ctx.beginPath();
    pts.forEach((p, i) => (i ? ctx.lineTo(p[0] * k, p[1] * k) : ctx.moveTo(p[0] * k, p[1] * k)));
    ctx.closePath(); ctx.fillStyle = fill; ctx.fill();
    if (stroke) { ctx.strokeStyle = stroke; ctx.lineWidth = 1; ctx.stroke(); } };
  function draw() {
    const c = model.get("colors");
    ctx.fillStyle = "white"; ctx.fillRect(0, 0, size, size);
    poly(model.get("goal_outline"), rgb(c.goal));
    poly(model.get("block_outline"), rgb(c.block), "#333");
    const a = model.get("agent");
    ctx.beginPath(); ctx.arc(a[0] * k, a[1] * k, model.get("agent_radius") * k, 0, 2 * Math.PI);
    ctx.fillStyle = rgb(c.agent); ctx.fill();
    if (target) { const r = 6; ctx.strokeStyle = rgb(c.target); ctx.lineWidth = 2; ctx.beginPath();
      ctx.moveTo(target[0] * k - r, target[1] * k - r); ctx.lineTo(target[0] * k + r, target[1] * k + r);
      ctx.moveTo(target[0] * k - r, target[1] * k + r); ctx.lineTo(target[0] * k + r, target[1] * k - r);
      ctx.stroke(); }
    const rec = model.get("recording");
    readout.textContent = `coverage ${model.get("coverage").toFixed(3)} (best ${model.get("best_coverage").toFixed(3)})` +
      ` | step ${model.get("n_steps")} | kept ${model.get("n_kept")} | ${model.get("status")}`;
    start.disabled = rec; stop.disabled = !rec; discard.disabled = !rec;
  }
  // Mouse -> world through the size the canvas is SHOWN at (its content box, inside the border;
  // the ratio to offsetWidth undoes a CSS zoom or transform), never through `size`.
  const world = (ev) => {
    const r = canvas.getBoundingClientRect();
    const sx = r.width / canvas.offsetWidth, sy = r.height / canvas.offsetHeight;
    return [(ev.clientX - r.left - canvas.clientLeft * sx) * 512 / (canvas.clientWidth * sx),
            (ev.clientY - r.top - canvas.clientTop * sy) * 512 / (canvas.clientHeight * sy)]; };
  canvas.addEventListener("pointerdown", (ev) => { if (!model.get("recording") && !starting) return;
    dragging = true; touched = true; target = world(ev); canvas.setPointerCapture?.(ev.pointerId); draw(); });
  canvas.addEventListener("pointermove", (ev) => { if (dragging) { target = world(ev); draw(); } });
  const release = () => { dragging = false; };
  canvas.addEventListener("pointerup", release);
  canvas.addEventListener("pointercancel", release);
  start.addEventListener("click", () => { touched = false; target = null; pending = false; starting = true;
    model.send({ event: "start" }); });
  stop.addEventListener("click", () => model.send({ event: "stop" }));
  discard.addEventListener("click", () => model.send({ event: "discard" }));
  const timer = setInterval(() => {
    if (!model.get("recording") || !touched || pending || !target) return;
    pending = true;  // one control step at a time: wait for Python's answer
    model.send({ event: "tick", target: target });
  }, 1000 / model.get("hz"));
  for (const name of ["n_steps", "status"]) model.on("change:" + name, () => { pending = false; });
  model.on("change:recording", () => { pending = false; starting = false;
    if (!model.get("recording")) { touched = false; } draw(); });
  for (const name of ["agent", "block_outline", "coverage", "n_kept", "status"]) model.on("change:" + name, draw);
  draw();
  return () => clearInterval(timer);
}
export default { render };
"""


class TeleopWidget(anywidget.AnyWidget):
    """Drag the pusher with the mouse; every 1/10 s one control step runs in Python and is recorded.

    Args:
        path: optional ``.npz`` the kept episodes go to after every Stop (an earlier recording
            there is extended, see :class:`~coursekit.teleop.TeleopRecorder`).
        first_seed, reset_state, config: as :class:`~coursekit.teleop.TeleopRecorder`.
        size: canvas width and height in screen pixels (the world is 512 x 512); an output area
            narrower than that shows it smaller, and the mouse maps through the size shown.

    ``widget.recorder`` is the recorder (``.dataset()``, ``.episodes``, ``.save()``); it can also be
    driven without a browser (``widget.recorder.record(targets)``), and the widget shows the result.
    """

    _esm = _ESM
    size = traitlets.Int(400).tag(sync=True)
    hz = traitlets.Float(PUSHT.control_hz).tag(sync=True)
    agent = traitlets.List([256.0, 400.0]).tag(sync=True)
    agent_radius = traitlets.Float(geo.AGENT_RADIUS).tag(sync=True)
    block_outline = traitlets.List([]).tag(sync=True)
    goal_outline = traitlets.List([]).tag(sync=True)
    colors = traitlets.Dict({}).tag(sync=True)
    coverage = traitlets.Float(0.0).tag(sync=True)
    best_coverage = traitlets.Float(0.0).tag(sync=True)
    n_steps = traitlets.Int(0).tag(sync=True)
    n_kept = traitlets.Int(0).tag(sync=True)
    recording = traitlets.Bool(False).tag(sync=True)
    status = traitlets.Unicode("press Start, then drag the blue pusher").tag(sync=True)

    def __init__(self, path=None, first_seed: int = 0, reset_state=None, config=None, size: int = 400, **kwargs):
        if isinstance(size, bool) or not isinstance(size, int) or not 128 <= size <= 2048:
            raise ValueError(f"size must be an int number of screen pixels in [128, 2048], got {size!r}")
        self.recorder = TeleopRecorder(path=path, first_seed=first_seed, reset_state=reset_state, config=config)
        super().__init__(size=size, **kwargs)
        self.goal_outline = geo.block_outline(geo.GOAL_POSE).tolist()
        self.colors = {"goal": list(GOAL_COLOR), "block": list(BLOCK_COLOR), "agent": list(AGENT_COLOR),
                       "target": list(TARGET_COLOR)}
        self.on_msg(self._on_message)
        self.recorder.preview()  # show where the first episode will begin
        self.sync()

    def sync(self) -> None:
        """Push the recorder's state to the page (called after every step; call it yourself
        after driving ``self.recorder`` from Python)."""
        r = self.recorder
        with self.hold_sync():
            s = r.state
            self.agent = [float(s[0]), float(s[1])]
            self.block_outline = geo.block_outline(s[2:5]).tolist()
            self.coverage = float(r.coverage)
            self.best_coverage = max(self.best_coverage, float(r.coverage)) if r.recording else float(r.coverage)
            self.n_kept = len(r.episodes)
            self.recording = r.recording
            self.n_steps = r.n_steps

    def _on_message(self, _widget, content, _buffers) -> None:
        event = content.get("event") if isinstance(content, dict) else None
        r = self.recorder
        if event == "start":
            r.start()
            self.best_coverage = float(r.coverage)
            self.status = "recording: drag the pusher"
        elif event == "tick" and r.recording:
            try:
                target = np.asarray(content.get("target"), dtype=np.float64)
            except (TypeError, ValueError):
                target = np.full(1, np.nan)
            if target.shape != (2,) or not np.all(np.isfinite(target)):
                self.status = f"ignored a bad target {content.get('target')!r} (expected [x, y])"
            elif not r.step(target):  # the episode ended by itself and was kept
                self.status = (f"kept episode {len(r.episodes) - 1}: "
                               f"{'success' if r.success_steps[-1] is not None else 'max steps'}")
        elif event == "stop" and r.recording:
            index = r.stop()
            self.status = "nothing to keep (no step)" if index is None else f"kept episode {index}"
        elif event == "discard" and r.recording:
            r.discard()
            self.status = "discarded"
        self.sync()

    def dataset(self):
        """The kept episodes as an ``EpisodeDataset``."""
        return self.recorder.dataset()
