"""PushT figures with matplotlib: the scene, rollouts as notebook animations, coverage curves and
pusher paths of several episodes overlaid.

Everything builds ``matplotlib.figure.Figure`` objects directly (never pyplot), so it is
Agg-safe, leaves no global figure registry behind and never calls ``show()``: functions
return the Figure (or draw into an ``ax`` you pass). World coordinates are the env's: 512 x 512,
y DOWN, so every axis here is drawn with y inverted, like the rendered images.

A state is ``[agent_x, agent_y, block_x, block_y, block_angle, ...]`` (the first 5 entries of
``PushTEnv.get_state()`` or a dataset's "state" row; extra entries are ignored).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from matplotlib.animation import FuncAnimation
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon, Rectangle

from coursekit.envs import pusht_geometry as geo
from coursekit.tasks.pusht import PUSHT

# The reference colours (same names as the rasteriser), as matplotlib colour strings.
GOAL_COLOR = "lightgreen"
BLOCK_COLOR = "lightslategray"
BLOCK_EDGE = "#485460"
AGENT_COLOR = "royalblue"
TARGET_COLOR = "crimson"
WALL_COLOR = "lightgray"


def _states(states) -> np.ndarray:
    s = np.asarray(states, dtype=np.float64)
    if s.ndim != 2 or s.shape[1] < 5 or len(s) == 0:
        raise ValueError(f"states must be (T, >=5) with T >= 1, got shape {s.shape}")
    return s[:, :5]  # (T, 5)


def _new_axes(ax: Axes | None, figsize=(4.0, 4.0)) -> tuple[Figure, Axes]:
    if ax is not None:
        return ax.figure, ax
    fig = Figure(figsize=figsize, layout="constrained")
    return fig, fig.add_subplot()


def setup_world_axes(ax: Axes, title: str | None = None) -> None:
    """World limits [0, 512]^2 with y down, equal aspect, no ticks clutter."""
    ax.set_xlim(0, geo.WORLD_SIZE)
    ax.set_ylim(geo.WORLD_SIZE, 0)  # y down, as in the images
    ax.set_aspect("equal")
    ax.set_xticks([0, 256, 512])
    ax.set_yticks([0, 256, 512])
    ax.tick_params(labelsize=7)
    if title:
        ax.set_title(title, fontsize=9)


@dataclass
class SceneArtists:
    """The patches of one drawn scene; ``update`` moves them (used by the animation)."""

    block: Polygon
    agent: Circle
    target: object | None = None
    extra: list = field(default_factory=list)

    def update(self, state, target=None) -> list:
        """Move block and pusher to ``state`` (and the target marker to ``target``)."""
        s = geo.as_state5(state)
        self.block.set_xy(geo.block_outline(s[2:5]))
        self.agent.center = (s[0], s[1])
        if self.target is not None:
            if target is None:
                self.target.set_data([], [])
            else:
                self.target.set_data([target[0]], [target[1]])
        return [self.block, self.agent] + ([self.target] if self.target is not None else [])


def draw_scene(ax: Axes, state, target=None, goal: bool = True, walls: bool = True,
               block_alpha: float = 1.0, agent_alpha: float = 1.0, show_target: bool | None = None,
               title: str | None = None) -> SceneArtists:
    """Draw goal T, block T and pusher of ``state`` (5,) into ``ax``; returns the artists.

    ``target`` (2,) marks the action target with a cross (``show_target`` forces the marker to
    exist even when ``target`` is None, for animations).
    """
    s = geo.as_state5(state)
    setup_world_axes(ax, title)
    if walls:
        lo, hi = geo.WALL_LO, geo.WALL_HI
        ax.add_patch(Rectangle((lo, lo), hi - lo, hi - lo, fill=False, edgecolor=WALL_COLOR,
                               linewidth=2, zorder=0))
    if goal:
        ax.add_patch(Polygon(geo.block_outline(geo.GOAL_POSE), closed=True, facecolor=GOAL_COLOR,
                             edgecolor="none", zorder=1))
    block = Polygon(geo.block_outline(s[2:5]), closed=True, facecolor=BLOCK_COLOR,
                    edgecolor=BLOCK_EDGE, linewidth=1.0, alpha=block_alpha, zorder=2)
    agent = Circle((s[0], s[1]), geo.AGENT_RADIUS, facecolor=AGENT_COLOR, edgecolor="none",
                   alpha=agent_alpha, zorder=4)
    ax.add_patch(block)
    ax.add_patch(agent)
    marker = None
    if target is not None or show_target:
        tx, ty = ([target[0]], [target[1]]) if target is not None else ([], [])
        (marker,) = ax.plot(tx, ty, marker="x", color=TARGET_COLOR, markersize=7, mew=2,
                            linestyle="none", zorder=5)
    return SceneArtists(block=block, agent=agent, target=marker)


def plot_scene(state, target=None, title: str | None = None, figsize=(4.0, 4.0)) -> Figure:
    """A new Figure showing one state (see ``draw_scene``)."""
    fig, ax = _new_axes(None, figsize)
    draw_scene(ax, state, target=target, title=title)
    return fig


# --------------------------------------------------------------------------------------------
# Rollouts
# --------------------------------------------------------------------------------------------
def animate_rollout(states, actions=None, coverage=None, stride: int = 1, interval_ms: int | None = None,
                    figsize=(3.6, 3.6), dpi: int = 72) -> FuncAnimation:
    """A ``FuncAnimation`` of a rollout: states (T, >=5), optional actions (T, 2) drawn as the
    target cross, optional coverage (T,) in the title. ``stride`` keeps every k-th frame.

    Default frame interval = real time (1 / ``PUSHT.control_hz`` per env step, times ``stride``).
    """
    s = _states(states)
    if stride < 1:
        raise ValueError(f"stride must be >= 1, got {stride!r}")
    a = None if actions is None else np.asarray(actions, dtype=np.float64)
    if a is not None and (a.ndim != 2 or a.shape[1] != 2 or len(a) > len(s)):
        raise ValueError(f"actions must be (T', 2) with T' <= {len(s)} states, got shape {a.shape}")
    c = None if coverage is None else np.asarray(coverage, dtype=np.float64)
    if c is not None and c.shape != (len(s),):
        raise ValueError(f"coverage must be ({len(s)},) like the states, got shape {c.shape}")
    frames = list(range(0, len(s), stride))
    if frames[-1] != len(s) - 1:
        frames.append(len(s) - 1)  # always show the final state

    fig = Figure(figsize=figsize, dpi=dpi, layout="constrained")
    ax = fig.add_subplot()
    artists = draw_scene(ax, s[0], show_target=a is not None)
    title = ax.set_title("", fontsize=9)

    def frame(i: int):
        target = a[i] if a is not None and i < len(a) else None
        changed = artists.update(s[i], target)
        text = f"step {i}"
        if c is not None:
            text += f"   coverage {c[i]:.2f}"
        title.set_text(text)
        return changed + [title]

    interval = interval_ms if interval_ms is not None else round(1000 * stride / PUSHT.control_hz)
    return FuncAnimation(fig, frame, frames=frames, interval=interval, blit=False)


def rollout_jshtml(states, actions=None, coverage=None, stride: int = 1, **kwargs) -> str:
    """The rollout animation as a self-contained JavaScript/HTML string (``to_jshtml``)."""
    anim = animate_rollout(states, actions, coverage, stride=stride, **kwargs)
    return anim.to_jshtml(default_mode="once")


def rollout_html(states, actions=None, coverage=None, stride: int = 1, **kwargs):
    """The rollout animation as an ``IPython.display.HTML`` object for a notebook cell."""
    from IPython.display import HTML

    return HTML(rollout_jshtml(states, actions, coverage, stride=stride, **kwargs))


# --------------------------------------------------------------------------------------------
# Curves and overlays
# --------------------------------------------------------------------------------------------
def plot_coverage(coverages, labels: Sequence[str] | None = None, ax: Axes | None = None,
                  figsize=(5.0, 3.0)) -> Figure:
    """Coverage over env steps for one (T,) or several episodes (list of (T_i,) arrays), with the
    0.95 success threshold marked."""
    if isinstance(coverages, np.ndarray) and coverages.ndim == 1:
        coverages = [coverages]
    curves = [np.asarray(c, dtype=np.float64) for c in coverages]
    if not curves or any(c.ndim != 1 for c in curves):
        raise ValueError("coverages must be a (T,) array or a non-empty list of (T_i,) arrays")
    if labels is not None and len(labels) != len(curves):
        raise ValueError(f"got {len(labels)} labels for {len(curves)} curves")
    fig, ax = _new_axes(ax, figsize)
    for i, c in enumerate(curves):
        ax.plot(np.arange(len(c)), c, lw=1.5, label=None if labels is None else labels[i])
    ax.axhline(geo.SUCCESS_THRESHOLD, color="k", ls="--", lw=1, label="success (0.95)")
    ax.set_xlabel(f"env step ({PUSHT.control_hz:g} Hz)")
    ax.set_ylabel("coverage of the goal T")
    ax.set_ylim(0, 1.02)
    ax.legend(fontsize=8, loc="lower right")
    return fig


def plot_trajectories(paths, scene_state=None, colors: Sequence | None = None,
                      labels: Sequence[str] | None = None, ax: Axes | None = None,
                      title: str | None = None, figsize=(4.5, 4.5), end_states=None) -> Figure:
    """Pusher paths of several episodes over one scene.

    Args:
        paths: list of (T_i, >=2) arrays; the first two columns are the pusher's x, y (a state
            array works as is).
        scene_state: (5,) state drawn underneath (default: the first path's first row, when it
            has >= 5 columns; else only the goal).
        colors: one colour per path (default: matplotlib's cycle); ``labels``: one label per
            path (repeated labels appear once in the legend, e.g. "clockwise"/"anticlockwise").
        end_states: optional list of final (5,) states; their blocks are drawn faintly.
    """
    arrs = [np.asarray(p, dtype=np.float64) for p in paths]
    if not arrs or any(p.ndim != 2 or p.shape[1] < 2 or len(p) == 0 for p in arrs):
        raise ValueError("paths must be a non-empty list of (T_i, >=2) arrays")
    for name, seq in (("colors", colors), ("labels", labels)):
        if seq is not None and len(seq) != len(arrs):
            raise ValueError(f"got {len(seq)} {name} for {len(arrs)} paths")
    fig, ax = _new_axes(ax, figsize)
    if scene_state is None and arrs[0].shape[1] >= 5:
        scene_state = arrs[0][0, :5]
    if scene_state is not None:
        draw_scene(ax, scene_state, agent_alpha=0.5, title=title)
    else:
        setup_world_axes(ax, title)
        ax.add_patch(Polygon(geo.block_outline(geo.GOAL_POSE), closed=True, facecolor=GOAL_COLOR,
                             edgecolor="none", zorder=1))
    for s in end_states or []:
        ax.add_patch(Polygon(geo.block_outline(geo.as_state5(s)[2:5]), closed=True, facecolor="none",
                             edgecolor=BLOCK_EDGE, ls=":", lw=0.8, zorder=2))
    seen = set()
    for i, p in enumerate(arrs):
        color = None if colors is None else colors[i]
        label = None
        if labels is not None and labels[i] not in seen:
            label = labels[i]
            seen.add(label)
        (line,) = ax.plot(p[:, 0], p[:, 1], lw=1.2, alpha=0.8, color=color, label=label, zorder=3)
        ax.plot(p[-1, 0], p[-1, 1], "o", ms=3, color=line.get_color(), zorder=3)
    if labels is not None:
        ax.legend(fontsize=8, loc="upper right")
    return fig


def plot_filmstrip(states, n_frames: int = 6, coverage=None, figsize_per=(2.0, 2.0)) -> Figure:
    """``n_frames`` evenly spaced snapshots of one rollout side by side."""
    s = _states(states)
    if n_frames < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames!r}")
    idx = np.unique(np.linspace(0, len(s) - 1, n_frames).round().astype(int))
    fig = Figure(figsize=(figsize_per[0] * len(idx), figsize_per[1]), layout="constrained")
    axes = fig.subplots(1, len(idx), squeeze=False)[0]
    for ax, i in zip(axes, idx):
        title = f"t={i}" + ("" if coverage is None else f"  cov {float(coverage[i]):.2f}")
        draw_scene(ax, s[i], title=title)
        ax.set_xticks([])
        ax.set_yticks([])
    return fig
