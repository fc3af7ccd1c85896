"""The results table: every row well-formed, and the README shows exactly what results.json holds."""

import json
import re

import pytest

from benchmarks import results

REQUIRED = {"section": str, "name": str, "unit": str, "target": str, "command": str, "note": str,
            "measured": str, "machine": str}


def test_every_row_has_the_schema():
    table = json.loads(results.RESULTS.read_text())
    assert table, "benchmarks/results.json is empty"
    for key, entry in table.items():
        assert key == f"{entry['section']}/{entry['name']}", key
        for field, kind in REQUIRED.items():
            assert isinstance(entry.get(field), kind), f"{key}: {field} missing or not {kind.__name__}"
        assert isinstance(entry["value"], (int, float, str)), key
        module = re.search(r"-m benchmarks\.((?:bench|check)_\w+)", entry["command"])  # check_*: needs PyPI, not run_all
        assert module, f"{key}: command {entry['command']!r} is not a benchmark"
        assert (results.ROOT / "benchmarks" / f"{module.group(1)}.py").is_file(), f"{key}: no benchmark {module.group(1)}"
        if "interval" in entry:
            lo, hi = entry["interval"]
            assert lo <= entry["value"] <= hi, f"{key}: interval {entry['interval']} misses {entry['value']}"
        if "n" in entry:
            assert isinstance(entry["n"], int) and entry["n"] > 0, key
        if entry["section"].startswith(("Claims", "Chunk ablation")):  # issue 16: every claim with its evidence
            assert {"interval", "n", "seeds"} <= set(entry), f"{key}: a claims row needs interval, n and seeds"
            learned = "clean expert" not in entry["note"]  # the expert's own statistics have no training seed
            assert not learned or "training seed" in entry["note"], f"{key}: say how many training seeds are behind it"


def test_readme_table_is_rendered_from_results_json():
    text = results.README.read_text()
    inside = text.split(results.START, 1)[1].split(results.END, 1)[0].strip()
    assert inside == results.render_table(), "README results table is stale: run `python -m benchmarks.results`"


def test_record_refuses_an_interval_that_misses_the_value(tmp_path, monkeypatch):
    monkeypatch.setattr(results, "RESULTS", tmp_path / "r.json")
    monkeypatch.setattr(results, "README", tmp_path / "README.md")
    with pytest.raises(ValueError, match="does not contain"):
        results.record("S", "x", 0.9, "", "cmd", interval=(0.1, 0.2), n=200)
    results.record("S", "x", 0.15, "", "cmd", interval=(0.1, 0.2), n=200, seeds="100000-100199")
    row = json.loads((tmp_path / "r.json").read_text())["S/x"]
    assert row["interval"] == [0.1, 0.2] and row["n"] == 200 and row["seeds"] == "100000-100199"


def _numbers(text):
    return [m.group(0) for m in re.finditer(r"(?<![\w.\-])\d+(?:\.\d+)?(?![\w.])", text)]


def _matches(quoted, values):
    decimals = len(quoted.split(".")[1]) if "." in quoted else 0
    q = float(quoted)
    return any(round(v, decimals) == q or round(100 * v, decimals) == q for v in values)


def test_readme_claims_cite_rows_that_hold_their_numbers():
    """Every number in the README's claims block is in a results row that its bullet names (by a
    [section/name] citation or a <!-- row: ... --> tag; tests/test_text_bound_to_rows.py checks each tag's own number)."""
    text = results.README.read_text()
    assert "<!-- claims:start -->" in text and "<!-- claims:end -->" in text
    block = text.split("<!-- claims:start -->", 1)[1].split("<!-- claims:end -->", 1)[0]
    table = json.loads(results.RESULTS.read_text())
    bullets = [b.split("\n\n", 1)[0] for b in re.split(r"\n- ", block)[1:]]  # a bullet ends at a blank line
    assert len(bullets) >= 3, "the claims block has no bullets"
    by_name = {row["name"]: key for key, row in table.items()}
    for bullet in bullets:
        cited = re.findall(r"\[([^\]]+/[^\]]+)\]", bullet)  # [section/name] of each row it rests on
        tags = re.findall(r"<!--\s*row:\s*(.*?)\s*(?:\|.*?)?-->", bullet, re.S)  # benchmarks/check_text.py's tags
        cited += [tag if tag in table else by_name.get(tag, tag) for tag in tags]
        assert cited, f"bullet cites no row: {bullet[:80]!r}"
        values = []
        for key in cited:
            assert key in table, f"cited row {key!r} is not in results.json"
            row = table[key]
            values += [float(row["value"])] if isinstance(row["value"], (int, float)) else []
            values += list(row.get("interval", [])) + ([row["n"]] if "n" in row else [])
            words = " ".join([row["name"], row["note"], row.get("seeds", "")]).replace("-", " ").replace("=", " ")
            values += [float(x) for x in _numbers(words)]
        prose = re.sub(r"\[[^\]]+/[^\]]+\]|<!--.*?-->", "", bullet, flags=re.S)
        for quoted in _numbers(prose):
            assert _matches(quoted, values), f"{quoted} in {bullet[:60]!r}... is in none of its rows {cited}"


def test_every_row_is_shown_in_the_readme_once(tmp_path, monkeypatch):
    """A gridded row (e.g. "Latency budget/<head>, <strategy>, d=<d>: score") appears as its cell;
    every other row as a line of its own; nothing in results.json is left out."""
    monkeypatch.setattr(results, "RESULTS", tmp_path / "r.json")
    monkeypatch.setattr(results, "README", tmp_path / "none.md")
    results.record("Latency budget", "PushT DP, sync, d=0: score", 0.941, "", "-m benchmarks.bench_latency --heads dp",
                   interval=(0.909, 0.97), n=200)
    results.record("Latency budget", "PushT DP, rtc, d=4: score", 0.742, "", "-m benchmarks.bench_latency --heads dp",
                   interval=(0.574, 0.892), n=20)
    results.record("Latency budget", "PushT DP, sync, d=4: smoothness",
                   "jump at switches 9.5 px (other steps 4.8), max jerk 51.7 px/step^3", "", "-m benchmarks.bench_latency")
    results.record("Latency budget", "PushT DP: ms per chunk", 58.8, "ms", "-m benchmarks.bench_latency")
    table = results.render_table()
    lines = table.splitlines()
    assert sum("ms per chunk" in line for line in lines) == 1
    score_grid = next(i for i, line in enumerate(lines) if "score vs delay d" in line)
    assert lines[score_grid + 2] == "| line | d=0 | d=4 |"
    assert "| PushT DP, rtc |  | 0.742 [0.574, 0.892] n=20 |" in lines
    assert "| PushT DP, sync | 0.941 [0.909, 0.97] n=200 |  |" in lines
    assert "| PushT DP, sync | 9.5 / 51.7 px |" in lines
