"""The results table: every number in the README's table comes from a benchmark through here.

``record(...)`` stores one figure in ``benchmarks/results.json`` (atomically, keyed by
``section/name``) together with the command that produced it; ``render_readme()`` rewrites the
README between the ``<!-- results:start -->`` and ``<!-- results:end -->`` markers.
"""

from __future__ import annotations

import json
import os
import platform
import re
import time
from pathlib import Path

from coursekit.atomic import atomic_write_text

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results.json"
README = ROOT / "README.md"
START, END = "<!-- results:start -->", "<!-- results:end -->"
GRID_SECTIONS = ("Latency budget",)
"""Sections whose "<row>, <strategy>, d=<d>: <figure>" rows the README shows as one grid per figure
(row x d) instead of one line each: the full rows, with notes and commands, stay in results.json."""
GRID_ROW = re.compile(r"^(?P<row>.+), (?P<strategy>[^,]+), d=(?P<d>\d+): (?P<figure>[^:]+)$")


def load() -> dict:
    if not RESULTS.exists():
        return {}
    return json.loads(RESULTS.read_text())


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else what ``platform`` knows: rows and golden files name it."""
    try:
        names = [ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                 if ln.startswith("model name")]
    except OSError:
        names = []
    return names[0] if names else (platform.processor() or platform.machine())


def record(section: str, name: str, value: float | str, unit: str, command: str,
           target: str = "", note: str = "", interval: tuple[float, float] | None = None,
           n: int | None = None, seeds: str = "") -> None:
    """Store one measured figure (and re-render the README table).

    Evaluation figures also give ``interval`` (95 %, in the figure's own unit: see
    :mod:`coursekit.stats`), ``n`` (episodes behind it) and ``seeds`` (which seeds, e.g.
    "100000-100199", so a reader can tell protocol seeds from validation seeds).
    """
    entry = {
        "section": section, "name": name, "value": value, "unit": unit, "target": target,
        "command": command, "note": note, "measured": time.strftime("%Y-%m-%d"),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, {cpu_model()}",
    }
    if interval is not None:
        lo, hi = (float(v) for v in interval)
        if not lo <= float(value) <= hi:
            raise ValueError(f"interval {interval!r} does not contain the value {value!r} ({section}/{name})")
        entry["interval"] = [lo, hi]
    if n is not None:
        if isinstance(n, bool) or int(n) != n or n <= 0:
            raise ValueError(f"n must be a positive integer, got {n!r} ({section}/{name})")
        entry["n"] = int(n)
    if seeds:
        entry["seeds"] = seeds
    table = load()
    table[f"{section}/{name}"] = entry
    atomic_write_text(RESULTS, json.dumps(table, indent=1, sort_keys=True) + "\n")
    render_readme()


def _fmt(v: float | str) -> str:
    if isinstance(v, float):
        return f"{v:.3g}" if abs(v) < 1000 else f"{v:,.0f}"
    return str(v)


def _cell(entry: dict) -> str:
    val = f"{_fmt(entry['value'])} {entry['unit']}".strip()
    if "interval" in entry:
        lo, hi = entry["interval"]
        val += f" [{_fmt(lo)}, {_fmt(hi)}]"
    return val + (f" n={entry['n']}" if "n" in entry else "")


def _short_smoothness(text: str) -> str:
    """'jump at switches 9.5 px (other steps 4.8), max jerk 51.7 px/step^3' -> '9.5 / 51.7 px'."""
    m = re.match(r"jump at switches ([\d.]+) (\w+) \(other steps (?:[\d.]+|nan)\), max jerk ([\d.]+)", str(text))
    return f"{m.group(1)} / {m.group(3)} {m.group(2)}" if m else str(text)


def _render_grids(entries: list[dict]) -> list[str]:
    """One markdown grid per (section, figure): a line per "<row>, <strategy>", a column per d."""
    grids: dict[tuple[str, str], dict] = {}
    for e in entries:
        m = GRID_ROW.match(e["name"])
        g = grids.setdefault((e["section"], m["figure"]), {"cells": {}, "ds": set(), "commands": set(), "dates": set()})
        g["cells"][(m["row"], m["strategy"], int(m["d"]))] = e
        g["ds"].add(int(m["d"]))
        g["commands"].add(e["command"].split(" --heads")[0])
        g["dates"].add(e["measured"])
    out = []
    for (section, figure), g in sorted(grids.items()):
        ds = sorted(g["ds"])
        lines = sorted({(r, st) for r, st, _ in g["cells"]})
        what = ("mean switch jump / largest jerk" if figure == "smoothness" else f"{figure} [95 % interval] n")
        out += ["", f"**{section}: {figure} vs delay d** (cell: {what}; every cell is the row "
                    f"\"{section}/<line>, d=<d>: {figure}\" of benchmarks/results.json, with its note and exact "
                    f"command; made by `{'`, `'.join(sorted(g['commands']))}`; measured "
                    f"{min(g['dates'])}{'' if len(g['dates']) == 1 else ' to ' + max(g['dates'])})", "",
                "| line | " + " | ".join(f"d={d}" for d in ds) + " |", "|---|" + "---|" * len(ds)]
        for r, st in lines:
            cells = [g["cells"].get((r, st, d)) for d in ds]
            shown = [("" if c is None else _short_smoothness(c["value"]) + (f" n={c['n']}" if "n" in c else "")
                      if figure == "smoothness" else "" if c is None else _cell(c)) for c in cells]
            out.append(f"| {r}, {st} | " + " | ".join(shown) + " |")
    return out


def render_table() -> str:
    rows = ["| section | figure | value | 95 % interval (n) | target | conditions | command |",
            "|---|---|---|---|---|---|---|"]
    gridded = []
    for entry in sorted(load().values(), key=lambda e: (e["section"], e["name"])):
        if entry["section"] in GRID_SECTIONS and GRID_ROW.match(entry["name"]):
            gridded.append(entry)
            continue
        val = f"{_fmt(entry['value'])} {entry['unit']}".strip()
        ci = ""
        if "interval" in entry:
            lo, hi = entry["interval"]
            ci = f"[{_fmt(lo)}, {_fmt(hi)}]"
        if "n" in entry:
            ci = f"{ci} (n={entry['n']}{', seeds ' + entry['seeds'] if entry.get('seeds') else ''})".strip()
        note = entry.get("note", "").replace("|", "/")
        rows.append(f"| {entry['section']} | {entry['name']} | {val} | {ci} | {entry['target']} | {note} "
                    f"(measured {entry['measured']}) | `{entry['command']}` |")
    return "\n".join(rows + _render_grids(gridded))


def render_readme() -> None:
    if not README.exists():
        return
    text = README.read_text()
    if START not in text or END not in text:
        return
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    atomic_write_text(README, f"{head}{START}\n{render_table()}\n{END}{tail}")


def drop(keys: list[str]) -> None:
    """Remove rows (``section/name`` keys) that no benchmark writes any more, e.g. after a rename."""
    table = load()
    unknown = [k for k in keys if k not in table]
    if unknown:
        raise KeyError(f"no such rows {unknown}; known: {sorted(table)}")
    for k in keys:
        del table[k]
    atomic_write_text(RESULTS, json.dumps(table, indent=1, sort_keys=True) + "\n")
    render_readme()


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description="maintain benchmarks/results.json and the README table")
    parser.add_argument("--drop", nargs="+", default=[], metavar="KEY", help="remove rows by 'section/name'")
    parser.add_argument("--list", action="store_true", help="print the row keys")
    args = parser.parse_args()
    if args.drop:
        drop(args.drop)
    if args.list:
        print("\n".join(sorted(load())))
    render_readme()
