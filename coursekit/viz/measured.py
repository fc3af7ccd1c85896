"""The course's own measurements as figures: rows of the repository's results table, with intervals.

The chapters argue from ``benchmarks/results.json`` (every row written by a command in
``benchmarks/``, with n, seeds and a 95 % interval), never from numbers typed into a cell. These
functions read the rows a figure needs and draw them with their intervals; a point measured on
fewer than 200 episodes says its n in the legend. A pip-installed coursekit has no table: the
readers return nothing and the figures say where the rows come from.

    load_rows(section)        {key: row} of one section (all sections when None)
    budget_curve(rows)        variant -> [(steps, value, lo, hi, n)]   (bench_chunk_ablation)
    by_data_set(rows, steps)  variant -> [(data set, value, lo, hi, n)]: the heads step for step on each data set
    leads_by_data_set(rows, steps)  "minus <head>, <starts>" -> [(data set, DP's paired lead, lo, hi, n)]
    chunk_sweep(rows, task)   executor -> [(k, value, lo, hi, n)], and the no-CVAE rows (bench_act_chunks)
    chunk_sweep_seeds(rows, task)  (executor, without CVAE?) -> [(k, each training seed's value)]: the spread a pooled interval hides
    side_by_side(rows)        task -> [(head, value, lo, hi, n)]: the shipped checkpoints (chapter 9)
    side_by_side(rows, PIXEL_ROUTES)  the same for chapter 12: the pixel routes beside the keypoint policy
    plot_points(ax, pts, ...) one series with its interval bars
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from coursekit.tasks import INSERTION, TRANSFER_CUBE

RESULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "results.json"
"""The results table of a repository checkout (absent from an installed package)."""
Point = tuple  # (x, value, lo, hi, n)

_BUDGET = re.compile(r"^(?P<variant>.+?) \(To=.*\) score, (?P<seeds>\d+) training seed\(s\), (?P<steps>\d+) steps$")
_DATA = re.compile(r"^(?P<variant>.+?) \(To=.*\) score, (?P<seeds>\d+) training seed\(s\), (?P<steps>\d+) steps"
                   r"(?P<person>, person-like demonstrations)?$")
DATA_SETS = ("scripted planner", "person-like")
"""The PushT demonstration sets of ``by_data_set``, in x order (``coursekit collect pusht`` without / with ``--style person``)."""
_PER_SEED = re.compile(r"per seed: (?P<values>-?[\d.]+(?: %)?(?:, -?[\d.]+(?: %)?)*)")
_LEAD = re.compile(r"^DP DDIM-10 minus (?P<other>.+?), (?P<seeds>\d+) training seed\(s\), (?P<steps>\d+) steps"
                   r"(?P<person>, person-like demonstrations)?, (?P<starts>two-way|other) starts$")
_CHUNK = re.compile(r"^ACT k=(?P<k>\d+)(?P<novae> without CVAE)?(?: on (?P<task>[a-z_]+))?, (?P<executor>.+): strict success$")
ARM_TASKS = (TRANSFER_CUBE.name, INSERTION.name)
"""The arm pair's tasks of the k sweep; rows on the first carry no task name ("ACT k=10, ..."), the others " on <task>"."""


def _chunk_row(row: dict[str, Any], task: str) -> re.Match | None:
    """The name's parts when ``row`` is a k-sweep row on ``task``, else None."""
    m = _CHUNK.match(row["name"]) if row["section"] == "Chunk ablation (arm pair)" else None
    return m if m and (m["task"] or ARM_TASKS[0]) == task else None


def load_rows(section: str | None = None, path: str | Path = RESULTS) -> dict[str, dict[str, Any]]:
    """The rows of ``section`` (all when None) keyed "Section/name"; {} when the table is not here."""
    path = Path(path)
    if not path.is_file():
        return {}
    table = json.loads(path.read_text(encoding="utf-8"))
    return {k: r for k, r in table.items() if section is None or r["section"] == section}


def _point(x: float, row: dict[str, Any], scale: float = 1.0) -> Point:
    lo, hi = row.get("interval") or (row["value"], row["value"])
    return (x, row["value"] * scale, lo * scale, hi * scale, row.get("n") or 0)


def budget_curve(rows: dict[str, dict[str, Any]]) -> dict[str, list[Point]]:
    """variant -> [(optimiser steps, mean score over training seeds, t-interval lo, hi, episodes)], by steps.

    Reads the "Chunk ablation (PushT)" rows "<variant> (To=..) score, <k> training seed(s), <N> steps"
    (``bench_chunk_ablation --name-budget``), all starts only.
    """
    curves: dict[str, list[Point]] = {}
    for row in rows.values():
        m = _BUDGET.match(row["name"]) if row["section"] == "Chunk ablation (PushT)" else None
        if m:
            curves.setdefault(m["variant"], []).append(_point(int(m["steps"]), row))
    return {v: sorted(p) for v, p in sorted(curves.items())}


def by_data_set(rows: dict[str, dict[str, Any]], steps: int = 6000) -> dict[str, list[Point]]:
    """variant -> [(index into DATA_SETS, mean score over training seeds, lo, hi, episodes)], by data set.

    Reads the same "Chunk ablation (PushT)" rows as :func:`budget_curve` at one budget ``steps``, with
    and without ", person-like demonstrations" (all starts only): the heads trained step for step on
    each set. A set whose rows are not in yet has no point.
    """
    out: dict[str, list[Point]] = {}
    for row in rows.values():
        m = _DATA.match(row["name"]) if row["section"] == "Chunk ablation (PushT)" else None
        if m and int(m["steps"]) == steps:
            out.setdefault(m["variant"], []).append(_point(int(bool(m["person"])), row))
    return {v: sorted(p) for v, p in sorted(out.items())}


def chunk_sweep(rows: dict[str, dict[str, Any]], task: str = ARM_TASKS[0]) -> tuple[dict[str, list[Point]], dict[str, Point]]:
    """ACT's k sweep on ``task`` as fractions: ({executor: [(k, ...)]}, {executor: no-CVAE point at k})."""
    sweep: dict[str, list[Point]] = {}
    no_vae: dict[str, Point] = {}
    for row in rows.values():
        m = _chunk_row(row, task)
        if m:
            point = _point(int(m["k"]), row, 0.01)  # stored in %
            if m["novae"]:
                no_vae[m["executor"]] = point
            else:
                sweep.setdefault(m["executor"], []).append(point)
    return {e: sorted(p) for e, p in sorted(sweep.items())}, no_vae


def leads_by_data_set(rows: dict[str, dict[str, Any]], steps: int = 6000) -> dict[str, list[Point]]:
    """"minus <head>, <two-way|other> starts" -> [(index into DATA_SETS, DP's lead, lo, hi, episodes)], by data set.

    Reads the paired rows "DP DDIM-10 minus <head>, <k> training seed(s), <N> steps[, person-like
    demonstrations], <two-way|other> starts" of ``bench_chunk_ablation --name-budget``: Diffusion
    Policy's score minus the regressor's, training seed by training seed, on the starts where the
    expert's first decision is a coin toss between the two ways round the T and on the others.
    """
    out: dict[str, list[Point]] = {}
    for row in rows.values():
        m = _LEAD.match(row["name"]) if row["section"] == "Chunk ablation (PushT)" else None
        if m and int(m["steps"]) == steps:
            out.setdefault(f"minus {m['other']}, {m['starts']} starts", []).append(_point(int(bool(m["person"])), row))
    return {label: sorted(p) for label, p in sorted(out.items())}


def per_seed(row: dict[str, Any], scale: float = 1.0) -> list[float]:
    """Each training seed's value, read from the row's note ("per seed: 40.0 %, 16.5 %, ..."), times ``scale``; [] when none."""
    m = _PER_SEED.search(row.get("note") or "")
    return [float(v.rstrip(" %")) * scale for v in m["values"].split(", ")] if m else []


def chunk_sweep_seeds(rows: dict[str, dict[str, Any]],
                      task: str = ARM_TASKS[0]) -> dict[tuple[str, bool], list[tuple[int, list[float]]]]:
    """(executor, without CVAE?) -> [(k, each training seed's strict success on ``task`` as a fraction)], by k.

    The rows of :func:`chunk_sweep` pool the seeds' episodes into one Wilson interval, which says how
    well the 600 episodes pin the pooled rate, not how much the rate moves from one training seed to
    the next; these points show the latter.
    """
    out: dict[tuple[str, bool], list[tuple[int, list[float]]]] = {}
    for row in rows.values():
        m = _chunk_row(row, task)
        values = per_seed(row, 0.01) if m else []  # stored in %
        if values:
            out.setdefault((m["executor"], bool(m["novae"])), []).append((int(m["k"]), values))
    return {key: sorted(points) for key, points in sorted(out.items())}


SHIPPED_ROWS = {  # task -> [(head label, row key)]: every shipped checkpoint's protocol row (200 episodes)
    "PushT (score: mean max coverage)": [
        ("Diffusion Policy, DDIM-10", "Diffusion Policy/shipped checkpoint score, DDIM-10 (notebook 05)"),
        ("Diffusion Policy from pixels, DDIM-10",
         "Pixels (PushT): two-stage route/shipped pixel checkpoint score, DDIM-10 (notebook 12)"),
        ("flow matching, Euler-10", "Flow matching/shipped flow checkpoint score, Euler-10 (notebook 10)"),
        ("chunked regression", "Diffusion Policy/shipped regression checkpoint score (notebook 05)"),
        ("ACT, ensembling", "ACT/ACT PushT score (mean of max coverage)"),
    ],
    "transfer cube (strict success)": [
        ("Diffusion Policy, DDIM-10", "ACT/DP transfer cube success (strict, DDIM-10, Ta=8)"),
        ("ACT, ensembling", "ACT/ACT transfer cube strict success, shipped checkpoint, temporal ensembling m=0.01"),
        ("ACT, open-loop chunks", "ACT/ACT transfer cube strict success, shipped checkpoint, open-loop chunks (Ta=k=100)"),
    ],
    "insertion (strict success)": [
        ("ACT, ensembling", "ACT/ACT insertion strict success, shipped checkpoint, temporal ensembling m=0.01"),
        ("ACT, open-loop chunks", "ACT/ACT insertion strict success, shipped checkpoint, open-loop chunks (Ta=k=100)"),
    ],
}
"""The chapter-9 comparison: which row scores each shipped head on each task."""

PIXEL_ROUTES = {  # chapter 12: Diffusion Policy from keypoints and from pixels, DDIM-10, Ta = 8, 200 protocol seeds
    "PushT (score: mean max coverage)": [
        ("keypoints: shipped, 19259 steps", "Diffusion Policy/shipped checkpoint score, DDIM-10 (notebook 05)"),
        ("pixels, two-stage: stage 1 + 19259 steps, encoder frozen",
         "Pixels (PushT): two-stage route/DP from pixels, two-stage: score"),
        ("pixels, end to end: 16600 steps, same CPU time", "Pixels (PushT): two-stage route/DP from pixels, end-to-end: score"),
    ],
}
"""The chapter-12 comparison (``benchmarks/bench_pixel_policy.py --only policy``; the end-to-end run's steps
are the two-stage route's CPU seconds at its own, slower step: ``benchmarks/long_runs.py``)."""


def side_by_side(rows: dict[str, dict[str, Any]],
                 table: dict[str, list[tuple[str, str]]] | None = None) -> dict[str, list[tuple]]:
    """task -> [(head, value, lo, hi, n)] of ``table``'s rows (default :data:`SHIPPED_ROWS`), as fractions
    (rows in % are divided by 100).

    A row missing from ``rows`` is left out (a pip-installed package has no table: every task is empty).
    """
    out: dict[str, list[tuple]] = {}
    for task, heads in (SHIPPED_ROWS if table is None else table).items():
        for head, key in heads:
            if key in rows:
                row = rows[key]
                out.setdefault(task, []).append((head, *_point(0, row, 0.01 if row.get("unit") == "%" else 1.0)[1:]))
    return out


def plot_points(ax: Any, points: list[Point], label: str, **style: Any) -> None:
    """Draw ``points`` (x, value, lo, hi, n) with 95 % interval bars; a thin n (< 200) joins the label."""
    if not points:
        return
    xs, vs, los, his, ns = zip(*points)
    thin = [n for n in ns if n < 200]
    label = label + (f" (n = {min(thin)}-{max(thin)} on some points)" if thin else "")
    ax.errorbar(xs, vs, yerr=[[v - lo for v, lo in zip(vs, los)], [hi - v for v, hi in zip(vs, his)]],
                capsize=3, label=label, **{"fmt": "o-", "ms": 4, **style})
