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
        module = re.search(r"-m benchmarks\.(bench_\w+)", entry["command"])
        assert module, f"{key}: command {entry['command']!r} is not a benchmark"
        assert (results.ROOT / "benchmarks" / f"{module.group(1)}.py").is_file(), f"{key}: no benchmark {module.group(1)}"
        if "interval" in entry:
            lo, hi = entry["interval"]
            assert lo <= entry["value"] <= hi, f"{key}: interval {entry['interval']} misses {entry['value']}"
        if "n" in entry:
            assert isinstance(entry["n"], int) and entry["n"] > 0, key


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
