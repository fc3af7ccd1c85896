"""Numbers in the course's prose, bound to the rows of ``benchmarks/results.json``.

Every measured number in a notebook's markdown and in the README's prose names the row it
comes from, in an HTML comment right after it (invisible when rendered; README, "Results"):

    DP scores 0.945 [0.913, 0.974]<!-- row: Claims (PushT, shipped checkpoints)/DP DDIM-10 score, all starts -->
    success 0.935<!-- row: Claims (PushT, shipped checkpoints)/DP DDIM-10 score, all starts | note: success -->
    LeRobot's ACT scored 87.6 %<!-- cite: LeRobot ACT model card, aloha_sim_transfer_cube_human, 500 episodes -->
    16x<!-- not-measured: (256 / 64)^2 channels -->

A tag names the row by its key ``Section/name`` or by its name alone when no other row has that
name. It binds the *figure* that ends right before it: a number, an optional ``%`` or unit and an
optional interval ``[lo, hi]``. ``row`` compares the figure with the row's value (and interval) at
the decimals written; ``| note: WORDS`` compares it with the numbers of the clause of the row's
note (between semicolons) that contains WORDS; a list of decimals ("40.0, 16.5, 16.5 %") must be a
run of those numbers in their order. A number written with ``%`` is compared in percent (94.5 %
against a value 0.945, or against 94.5 when the row's unit is ``%``), one without it as a
fraction (0.96 against 96 %). A number written without a sign is compared with the row's
magnitude (prose says "0.041 below"). ``cite`` marks a literature figure (name the paper or data
set and, as known, its demonstrations and episodes); ``not-measured`` a number that only looks
measured. A row measured on fewer than 200 episodes (its ``n``, or the note's "50 held-out
seeds") must have its n stated in the sentence ("on 50 held-out seeds", "n = 48").

What looks measured (and so needs a tag): a percentage (not "95 % interval"), a number in ms,
rad/s^3, px/step^3 or samples/s, a ratio like "2.5x", an interval with a decimal in it, and any
decimal. Not measurements: code and maths, a heading's or a table cell's leading item number
("## 5.6", "| 1.1 training windows"), a decimal after "=", "<", ">", "~", "+-" or after
exercise/section/chapter/Python/version, a parameter count or length ("4.5 M", "0.8 m") and a
control period ("100 ms per step"); write a setting as ``name = value`` or as code.

``python -m benchmarks.check_text`` prints every violation as ``file:cell:line: message``
(cell ``-`` in the README) and exits 1 if there is one; ``tests/test_text_bound_to_rows.py`` runs it.
"""

from __future__ import annotations

import json
import re
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
GENERATED = ("<!-- results:start -->", "<!-- results:end -->")
"""The README's results table is rendered from the rows (benchmarks/results.py): not prose."""
MIN_N = 200
"""A row on fewer episodes than this must have its n stated in the sentence that uses it."""

NUM = r"[+\-\u2212]?\d+(?:,\d{3})*(?:\.\d+)?"
DECIMAL = r"[+\-\u2212]?\d+\.\d+"
"""A list "0.788, 0.793, 0.795" binds as one figure only when every item is a decimal ("d = 8, 0.897" does not)."""
UNIT = r"(?:ms|s|x|px|rad/s\^3|rad/s\u00b3|px/step\^3|samples/s|steps/s|us|min|steps)"
TAG = re.compile(r"<!--\s*(row|cite|not-measured)\s*(?::\s*(.*?))?\s*-->", re.S)
FIGURE = re.compile(
    rf"(?:(?P<num>{DECIMAL}(?:,\s*{DECIMAL})+|{NUM})(?P<pct>\s?%)?(?:\s?{UNIT})?\s*)?"
    rf"(?:\[(?P<lo>{NUM})(?P<lopct>\s?%)?,\s*(?P<hi>{NUM})(?P<hipct>\s?%)?\](?:\s?{UNIT})?)?"
    r"[*_]*\s*$")
CODE = re.compile(r"```.*?```|`[^`]+`", re.S)
"""Code blocks and spans: neither prose numbers nor tags (the README shows the tag syntax in code)."""
MASKED = re.compile(r"\$\$.*?\$\$|\$[^$\n]+\$|<!--.*?-->|https?://\S+|\]\([^)]*\)", re.S)
"""Maths, comments, link targets: never prose numbers (a tag's own text is checked on its own)."""

NEVER_MEASURED_AFTER = re.compile(r"\s?(?:M\b|m\b|ms per (?:control )?step|ms period)")
"""Context after a number that makes it a parameter count (4.5 M), a length (0.8 m) or a control period."""
NEVER_MEASURED_BEFORE = re.compile(
    r"(?:[=<>\u2264\u2265\u2248~\u00b1]|[Ee]xercises?|[Ss]ections?|\u00a7|[Cc]hapters?|[Ss]ec\.|[Ee]q\.|"
    r"Table|Fig\.|Figure|Python|Ubuntu|[Vv]ersion|lerobot|MuJoCo|torch|ch\.)\s*$")
"""Context before a decimal that makes it a name, a version or a set value, not a measurement."""
CANDIDATES = [  # (what it looks like, pattern): each match outside a tag's figure needs a tag
    ("a percentage", re.compile(rf"(?<![\w.]){NUM}\s?%(?!\s*(?:t-)?(?:interval|confidence|CI|Wilson|bootstrap))")),
    ("a latency, jerk or rate", re.compile(
        rf"(?<![\w.]){NUM}\s?(?:ms|rad/s\^3|rad/s\u00b3|px/step\^3|samples/s|steps/s)(?!\w)")),
    ("a ratio", re.compile(r"(?<![\w.])\d+(?:\.\d+)?x(?!\w)")),
    ("an interval", re.compile(rf"\[(?=[^\]]*\.){NUM},\s*{NUM}\]")),
    ("a decimal", re.compile(r"(?<![\w.\-\u2212+])[+\-\u2212]?\d+\.\d+(?!\w|\.\d)")),
]
STATED_N = (r"(?:\bn\s*=\s*{n}\b|(?<![\w.]){n}\s+(?:[\w-]+\s+){{0,2}}"
            r"(?:episodes?|seeds?|starts?|rollouts?|runs?|trials?|samples?|chunks?|states?)\b)")
"""How a sentence states a row's n: "n = 48", "50 held-out seeds", "78 two-way starts"."""
NOTE_N = [re.compile(r"(\d+) held-out (?:seeds|episodes)"), re.compile(r"\bn\s*=\s*(\d+)"),
          re.compile(r"(\d+) (?:episodes|seeds|starts)\b")]
NOTE_SEED_RANGE = re.compile(r"seeds? (\d+)\s*\.\.\s*(\d+)")


@dataclass(frozen=True)
class Violation:
    """One problem: where (file, cell or '-', line in that cell or file) and what."""

    file: str
    cell: str
    line: int
    message: str

    def __str__(self) -> str:
        return f"{self.file}:{self.cell}:{self.line}: {self.message}"


def _float(text: str) -> float:
    return float(text.replace("\u2212", "-").replace(",", ""))


def _decimals(text: str) -> int:
    return len(text.split(".", 1)[1]) if "." in text else 0


def _close(written: str, written_pct: bool, target: float, target_pct: bool, signed: bool = True) -> bool:
    """``written`` rounds to ``target`` at its own decimals; percent and fraction compared alike."""
    w, t = _float(written), float(target)
    if not signed and written.lstrip()[0] not in "+-\u2212":
        t = abs(t)
    scale_w, scale_t = (0.01 if written_pct else 1.0), (0.01 if target_pct else 1.0)
    tol = 0.5 * 10 ** -_decimals(written) * scale_w
    return abs(w * scale_w - t * scale_t) <= tol + 1e-9 * max(1.0, abs(t * scale_t))


def row_n(row: dict) -> int | None:
    """The episodes behind a row: its ``n``, else the note's "50 held-out seeds" / "seeds 0..99"."""
    if "n" in row:
        return int(row["n"])
    note = row.get("note", "")
    for pattern in NOTE_N:
        m = pattern.search(note)
        if m:
            return int(m.group(1))
    m = NOTE_SEED_RANGE.search(note)
    return int(m.group(2)) - int(m.group(1)) + 1 if m else None


def _blank(pattern: re.Pattern, text: str) -> str:
    """``text`` with every match of ``pattern`` blanked out (offsets and newlines kept)."""
    return pattern.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), text)


def _sentence(visible: str, pos: int) -> str:
    """The sentence around ``pos``: a table row (with its header), a list item or a full stop's span."""
    line_start = visible.rfind("\n", 0, pos) + 1
    line_end = visible.find("\n", pos)
    line = visible[line_start:None if line_end < 0 else line_end]
    if line.lstrip().startswith("|"):
        lines = visible[:line_start].splitlines()
        header = next((lines[i - 1] for i in range(len(lines) - 1, 0, -1)
                       if re.match(r"\s*\|[\s|:-]+\|\s*$", lines[i])), "")
        return header + "\n" + line
    stops = r"(?:[.!?:]\s+(?=[A-Z*`(])|\n\s*\n|\n\s*(?:[*\-]|\d+\.)\s)"
    start = max((m.end() for m in re.finditer(stops, visible[:pos])), default=0)
    end = re.search(stops, visible[pos:])
    return visible[start:pos + (end.start() if end else len(visible) - pos)]


def _values_of(row: dict, selector: str | None) -> tuple[list[float], bool, list[float] | None]:
    """(values a figure's number may equal, are they in percent, the row's interval or None)."""
    if selector is None:
        if isinstance(row["value"], str):
            return [_float(x) for x in re.findall(NUM, row["value"])], False, None
        return [float(row["value"])], row.get("unit") == "%", row.get("interval")
    note = row.get("note", "")
    at = note.find(selector)
    if at < 0:
        raise KeyError(selector)
    end = note.find(";", at + len(selector))
    clause = note[note.rfind(";", 0, at) + 1:None if end < 0 else end]
    return [_float(x) for x in re.findall(NUM, clause)], "%" in clause, None


def _in_order(written: list[str], pct: bool, values: list[float], in_pct: bool) -> bool:
    """Whether the numbers ``written`` equal consecutive ``values`` in order."""
    return any(all(_close(w, pct, v, in_pct, signed=False) for w, v in zip(written, values[i:i + len(written)]))
               for i in range(len(values) - len(written) + 1))


def _check_row_tag(body: str, fig: re.Match, table: dict, sentence: str) -> list[str]:
    """Problems with one ``row`` tag and the figure it binds."""
    key, _, selector = (part.strip() for part in body.partition("|"))
    rows = [table[key]] if key in table else [r for r in table.values() if r.get("name") == key]
    if len(rows) != 1:
        return [f"tag names {'no' if not rows else 'more than one'} row of benchmarks/results.json: {key!r}"]
    row = rows[0]
    if selector and not selector.startswith("note:"):
        return [f"unknown selector {selector!r} (expected '| note: WORDS') in the tag of {key!r}"]
    try:
        values, in_pct, interval = _values_of(row, selector[5:].strip() if selector else None)
    except KeyError:
        return [f"the note of {key!r} has no {selector[5:].strip()!r}"]
    pct = bool(fig["pct"] or fig["lopct"] or fig["hipct"])
    problems = []
    shown = f"value {row['value']!r} {row.get('unit', '')}".strip() if not selector else selector
    written_all = re.findall(NUM, fig["num"] or "")
    for written in written_all:
        if not any(_close(written, pct, v, in_pct, signed=False) for v in values):
            problems.append(f"{written}{' %' if pct else ''} is not {key!r} ({shown}: {values})")
    if len(written_all) > 1 and not problems and not _in_order(written_all, pct, values, in_pct):
        # a list ("per seed: 40.0, 16.5, 16.5 %") is the row's list, in its order, not numbers found anywhere in it
        problems.append(f"{', '.join(written_all)} is not a run of {key!r} in order ({shown}: {values})")
    if fig["lo"]:
        bounds = interval if interval is not None else values
        for written in (fig["lo"], fig["hi"]):
            if not bounds or not any(_close(written, pct, b, in_pct) for b in bounds):
                problems.append(f"interval bound {written} is not in {key!r} (interval {bounds})")
    n = row_n(row)
    if n is not None and n < MIN_N and not re.search(STATED_N.format(n=n), sentence):
        problems.append(f"{key!r} rests on n = {n} < {MIN_N}: the sentence must state it ('n = {n}', '{n} episodes')")
    return problems


def check_markdown(text: str, table: dict) -> list[tuple[int, str]]:
    """Every problem in one markdown text as (line number from 1, message)."""
    prose = _blank(CODE, text)
    visible = _blank(MASKED, prose)
    covered = [False] * len(text)
    problems: list[tuple[int, str]] = []

    def line_of(pos: int) -> int:
        return text.count("\n", 0, pos) + 1

    for tag in TAG.finditer(prose):
        kind, body = tag.group(1), (tag.group(2) or "").strip()
        head = max(0, tag.start() - 200)
        fig = FIGURE.search(visible, head, tag.start())
        if not fig or not (fig["num"] or fig["lo"]):
            problems.append((line_of(tag.start()), f"<!-- {kind} --> follows no number"))
            continue
        for i in range(fig.start(), tag.start()):
            covered[i] = True
        if kind == "row":
            sentence = _sentence(visible, fig.start())
            problems += [(line_of(tag.start()), p) for p in _check_row_tag(body, fig, table, sentence)]
        elif kind == "cite" and len(body) < 8:
            problems.append((line_of(tag.start()), "a cite tag names its source (paper or data set, demos, episodes)"))
    for what, pattern in CANDIDATES:
        for m in pattern.finditer(visible):
            if any(covered[m.start():m.end()]) or _exempt(visible, m):
                continue
            problems.append((line_of(m.start()), f"{m.group(0).strip()!r} looks measured ({what}) but names no row"))
    return sorted(set(problems))


def _exempt(visible: str, m: re.Match) -> bool:
    """A decimal that is a heading's number, a version or a set value (``m = 0.01``), not a measurement."""
    line_start = visible.rfind("\n", 0, m.start()) + 1
    before = visible[line_start:m.start()]
    after = visible[m.end() - (2 if m.group(0).endswith("ms") else 0):m.end() + 24]
    if re.fullmatch(r"\s*#+\s*", before) or NEVER_MEASURED_AFTER.match(after):
        return True  # a heading's number, a parameter count, a length, a control period
    if re.search(r"\|\s*$", before) and re.match(r"[\s,]*[\"A-Za-z]", visible[m.end():]):
        return True  # a numbered item at the start of a table cell: "| 5.6 The Ta knob |"
    return bool(NEVER_MEASURED_BEFORE.search(before[-12:]))


def readme_prose(text: str) -> str:
    """The README without its generated results table (blank lines keep the line numbers)."""
    start, end = GENERATED
    if start not in text or end not in text:
        return text
    head, rest = text.split(start, 1)
    body, tail = rest.split(end, 1)
    return head + "\n" * body.count("\n") + tail


def check_repo(root: Path = ROOT) -> list[Violation]:
    """Every violation in the notebooks' markdown cells and the README's prose."""
    table = json.loads((root / "benchmarks" / "results.json").read_text())
    found = []
    readme = root / "README.md"
    for line, message in check_markdown(readme_prose(readme.read_text()), table):
        found.append(Violation("README.md", "-", line, message))
    for path in sorted((root / "notebooks").glob("*.ipynb")):
        cells = json.loads(path.read_text())["cells"]
        for index, cell in enumerate(cells):
            if cell["cell_type"] == "markdown":
                for line, message in check_markdown("".join(cell["source"]), table):
                    found.append(Violation(f"notebooks/{path.name}", str(index), line, message))
    return found


def main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(description="list numbers in the course's prose that are not bound to their rows")
    parser.add_argument("--root", type=Path, default=ROOT, help="repository root (default: this checkout)")
    found = check_repo(parser.parse_args(argv).root)
    for v in found:
        print(v)
    summary = f"{len(found)} number(s) in the text not bound to their rows" if found else "every number is bound to its row"
    print(summary, file=sys.stderr)
    return 1 if found else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
