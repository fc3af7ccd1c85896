"""Figures of the scripted PushT expert: two ways round the T from one start, and how often the
demonstrations face such a choice.

Diffusion Policy's argument rests on multimodal demonstrations: from the same state, some go
one way and some the other, and a mean-regression policy that averages them drives straight
into the T. The scripted expert is multimodal on purpose (a seeded coin picks a side when both
are about equally long, ``coursekit.experts.pusht_planner``); these figures show it.

Figures are built as ``matplotlib.figure.Figure`` objects (Agg-safe, never ``show()``).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from coursekit.envs import pusht_geometry as geo
from coursekit.tasks.pusht import PUSHT
from coursekit.viz.pusht_plots import BLOCK_EDGE, draw_scene

SIDE_COLORS = {"cw": "tab:orange", "ccw": "tab:purple", None: "tab:gray"}
SIDE_LABELS = {"cw": "clockwise", "ccw": "anticlockwise", None: "no choice"}


def expert_runs_from(start_state: Sequence[float], coin_seeds: Iterable[int], expert=None) -> list:
    """Expert episodes (``EpisodeRecord``) from one reset state (5,) [ax, ay, bx, by, angle],
    one per coin seed: the same start, only the coin differs."""
    from coursekit.envs.pusht import PushTEnv
    from coursekit.experts.pusht_planner import PushTExpert

    start = np.asarray(start_state, dtype=np.float64)
    if start.shape != (5,) or not np.all(np.isfinite(start)):
        raise ValueError(f"start_state must be a finite (5,) [ax, ay, bx, by, angle], got {start_state!r}")
    expert = expert or PushTExpert()
    env = PushTEnv(obs_type="state")
    return [expert.run_episode(env, reset_state=start, coin_seed=int(c)) for c in coin_seeds]


def _first_side(record) -> str | None:
    return record.route_choices[0]["taken"] if record.route_choices else None


def plot_two_ways(start_state: Sequence[float] | None = None, coin_seeds: Iterable[int] = range(8),
                  records: list | None = None, figsize=(9.0, 4.5)) -> Figure:
    """Several expert runs from ONE start, overlaid: pusher paths coloured by the side the coin
    chose at the first route round the T (bold up to the first push), and coverage over time.

    ``start_state`` defaults to ``pusht_planner.TWO_WAY_START``; pass ``records`` (from
    ``expert_runs_from``) to reuse runs already made.
    """
    from coursekit.experts.pusht_planner import PUSH, TWO_WAY_START

    start = np.asarray(TWO_WAY_START if start_state is None else start_state, dtype=np.float64)
    records = records if records is not None else expert_runs_from(start, coin_seeds)
    if not records:
        raise ValueError("need at least one expert run (coin_seeds was empty)")
    fig = Figure(figsize=figsize, layout="constrained")
    ax_paths, ax_cov = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.0, 1.1]})
    draw_scene(ax_paths, records[0].states[0], agent_alpha=0.5,
               title=f"{len(records)} expert runs from one start")
    seen = set()
    for rec in records:
        side = _first_side(rec)
        color = SIDE_COLORS[side]
        label = None if side in seen else SIDE_LABELS[side]
        seen.add(side)
        # The first way round (up to the first push) bold, the rest of the episode thin.
        pushes = np.flatnonzero(rec.phases == PUSH)
        first_push = int(pushes[0]) if len(pushes) else len(rec.states) - 1
        ax_paths.plot(rec.states[: first_push + 1, 0], rec.states[: first_push + 1, 1], color=color, lw=2.2,
                      alpha=0.8, label=label, zorder=3)
        ax_paths.plot(rec.states[first_push:, 0], rec.states[first_push:, 1], color=color, lw=0.8, alpha=0.5, zorder=3)
        final = rec.states[-1]
        ax_paths.plot(final[0], final[1], "o", ms=3, color=color, zorder=3)
        ax_paths.add_patch(_outline(geo.block_outline(final[2:5])))
        steps = np.arange(len(rec.coverage))
        ax_cov.plot(steps, rec.coverage, color=color, lw=1.2, alpha=0.8)
    ax_paths.legend(fontsize=8, loc="upper right")
    ax_cov.axhline(0.95, color="k", ls="--", lw=0.8)
    ax_cov.text(0, 0.955, "success (0.95)", fontsize=7, va="bottom")
    ax_cov.set_xlabel(f"env step ({PUSHT.control_hz:g} Hz)")
    ax_cov.set_ylabel("coverage of the goal T")
    ax_cov.set_ylim(0, 1.02)
    ax_cov.set_title("same start, the coin decides the way round", fontsize=9)
    return fig


def _outline(points: np.ndarray) -> Polygon:
    return Polygon(points, closed=True, facecolor="none", edgecolor=BLOCK_EDGE, ls=":", lw=0.8, zorder=2)


def plot_choice_summary(route_choices: Sequence[Sequence[dict]], ax=None, figsize=(4.0, 3.0)) -> Figure:
    """Bar chart over a dataset's episodes (``dataset.meta["route_choices"]``): no two-way
    choice, first choice clockwise, first choice anticlockwise."""
    sides = [(episode[0].get("taken", episode[0]["side"]) if episode else None) for episode in route_choices]
    if not sides:
        raise ValueError("route_choices is empty: pass dataset.meta['route_choices']")
    if ax is None:
        fig = Figure(figsize=figsize, layout="constrained")
        ax = fig.subplots()
    else:
        fig = ax.figure
    keys = [None, "cw", "ccw"]
    counts = [sides.count(k) for k in keys]
    bars = ax.bar([SIDE_LABELS[k] for k in keys], counts, color=[SIDE_COLORS[k] for k in keys])
    for bar, n in zip(bars, counts):
        ax.text(bar.get_x() + bar.get_width() / 2, n, f"{n / len(sides):.0%}", ha="center", va="bottom", fontsize=8)
    ax.set_ylabel("episodes")
    ax.set_title(f"route choices in {len(sides)} demonstrations", fontsize=9)
    return fig
