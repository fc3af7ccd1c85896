"""Every measured number in the notebooks' markdown and the README's prose names its results row.

The tags and their rules are documented in benchmarks/check_text.py and the README's "Results";
these tests run the checker on the real text and prove, on copies of real tagged sentences, that
it fails: a changed digit, a missing tag, a row that does not exist, a small n left unsaid.
"""

import json
import re
import subprocess
import sys

import pytest

from benchmarks import check_text
from benchmarks.check_text import check_markdown

ROOT = check_text.ROOT
TABLE = json.loads((ROOT / "benchmarks" / "results.json").read_text())
TAG = re.compile(r"<!-- row: (?P<body>.*?) -->")


def _texts():
    """(where, text) for the README's prose and every notebook markdown cell."""
    yield "README.md", check_text.readme_prose((ROOT / "README.md").read_text())
    for path in sorted((ROOT / "notebooks").glob("*.ipynb")):
        for i, cell in enumerate(json.loads(path.read_text())["cells"]):
            if cell["cell_type"] == "markdown":
                yield f"{path.name}:{i}", "".join(cell["source"])


def _real(tag_body):
    """A real markdown text of the course that holds ``<!-- row: tag_body -->``."""
    return next(text for _, text in _texts() if f"<!-- row: {tag_body} -->" in text)


def _messages(text, table=TABLE):
    return [message for _, message in check_markdown(text, table)]


def test_every_notebook_and_the_readme_bind_their_numbers():
    found = check_text.check_repo()
    assert not found, "numbers not bound to their rows:\n" + "\n".join(map(str, found))


SHIPPED_DP = "Claims (PushT, shipped checkpoints)/DP DDIM-10 score, all starts"
SENTENCE = f"0.945 [0.913, 0.974]<!-- row: {SHIPPED_DP} -->"


def test_a_changed_digit_in_a_real_sentence_is_reported():
    text = _real(SHIPPED_DP)
    assert SENTENCE in text and _messages(text) == []
    for changed in ("0.946 [0.913, 0.974]", "0.945 [0.903, 0.974]", "0.945 [0.913, 0.975]"):
        messages = _messages(text.replace(SENTENCE, changed + SENTENCE[len("0.945 [0.913, 0.974]"):]))
        assert len(messages) == 1 and SHIPPED_DP in messages[0], (changed, messages)


def test_every_bound_number_is_load_bearing():
    """Mutating the last digit of any tagged figure anywhere in the course makes the checker fail."""
    survivors = []
    for where, text in _texts():
        for tag in TAG.finditer(text):
            fig = check_text.FIGURE.search(text, max(0, tag.start() - 200), tag.start())
            at = fig.end("hi" if fig["hi"] else "num") - 1  # the last digit of the figure's last number
            mutated = text[:at] + str((int(text[at]) + 5) % 10) + text[at + 1:]
            if not _messages(mutated):
                survivors.append(f"{where}: {text[fig.start():tag.end()]}")
    assert not survivors, "tags whose number can change unnoticed:\n" + "\n".join(survivors)


def test_an_untagged_measurement_is_reported():
    text = _real(SHIPPED_DP).replace(f"<!-- row: {SHIPPED_DP} -->", "", 1)
    assert any("'0.945' looks measured" in m for m in _messages(text))
    for untagged in ("scores 94.5 % here", "takes 58.8 ms per chunk", "2.5x faster", "lies in [0.91, 0.97]"):
        assert _messages(untagged), untagged


def test_a_tag_naming_no_row_is_reported():
    text = _real(SHIPPED_DP).replace(SHIPPED_DP, SHIPPED_DP + " (retired)", 1)
    assert any("names no row" in m and "(retired)" in m for m in _messages(text))


def test_a_small_n_left_unsaid_is_reported():
    body = "DP DDIM-10 minus chunked regression, two-way starts"  # a subset row: 78 of the 200 protocol seeds
    stated = "on the 78 two-way starts"
    text = next(t for _, t in _texts() if f"<!-- row: {body} -->" in t and stated in t)
    assert _messages(text) == []
    messages = _messages(text.replace(stated, "on the two-way starts"))
    assert len(messages) == 1 and "n = 78 < 200" in messages[0], messages
    assert check_text.row_n(TABLE["Claims (PushT, shipped checkpoints)/" + body]) == 78


TOY = {"S/score": {"section": "S", "name": "score", "value": 0.945, "unit": "", "interval": [0.913, 0.974], "n": 200,
                   "note": "success 0.935 [0.892, 0.962] (n=200); per seed: 0.788, 0.793"},
       "S/rate": {"section": "S", "name": "rate", "value": 96.0, "unit": "%", "note": "50 held-out episodes"},
       "S/minus": {"section": "S", "name": "minus", "value": -0.041, "unit": "", "n": 200, "note": ""}}


@pytest.mark.parametrize("text, ok", [
    ("94.5 %<!-- row: S/score -->", True),          # percent written, fraction stored
    ("94.6 %<!-- row: S/score -->", False),
    ("0.9<!-- row: score -->", True),                # fewer decimals written; the name alone
    ("0.95<!-- row: score -->", True),
    ("0.96<!-- row: score -->", False),
    ("0.96 on 50 episodes<!-- row: rate -->", False),   # the tag binds the number right before it
    ("0.96<!-- row: rate --> on 50 episodes", True),    # fraction written, percent stored
    ("96 %<!-- row: rate --> (n = 50)", True),
    ("96 %<!-- row: rate -->", False),                  # 50 episodes, not stated
    ("0.041 below<!-- row: minus -->", False),
    ("0.041<!-- row: minus --> below", True),            # no sign written: the magnitude
    ("-0.041<!-- row: minus -->", True),
    ("+0.041<!-- row: minus -->", False),
    ("0.945 [0.913, 0.974]<!-- row: score -->", True),
    ("0.945 [0.913, 0.975]<!-- row: score -->", False),
    ("success 0.935<!-- row: score | note: success -->", True),
    ("success 0.936<!-- row: score | note: success -->", False),
    ("0.788, 0.793<!-- row: score | note: per seed -->", True),
    ("0.788, 0.794<!-- row: score | note: per seed -->", False),
    ("0.793, 0.788<!-- row: score | note: per seed -->", False),  # a list is the row's list, in its order
    ("0.935, 0.788<!-- row: score -->", False),
    ("0.935<!-- row: score | note: no such words -->", False),
    ("87.6 %<!-- cite: LeRobot PR #319, 500 episodes -->", True),
    ("87.6 %<!-- cite: x -->", False),
    ("16x<!-- not-measured: (256 / 64)^2 -->", True),
    ("a tag after words<!-- row: score -->", False),
])
def test_the_rules_on_small_texts(text, ok):
    assert (_messages(text, TOY) == []) == ok, _messages(text, TOY)


@pytest.mark.parametrize("text", [
    "## 5.6 The Ta knob", "Exercise 10.1 and section 5.7", "| 1.1 training windows |", "m = 0.01, beta = 10",
    "success when coverage > 0.95", "4.5 M parameters, 0.8 m above", "at 10 Hz it has 100 ms per step",
    "`lr=1e-4, betas=(0.95, 0.999)`", "$\\bar\\alpha_{99} \\approx 0.025$", "95 % interval", "Python 3.11",
    "```\nscored 0.945 in 5.2 ms\n```",
])
def test_names_settings_and_code_are_not_measurements(text):
    assert _messages(text, TOY) == []


def test_the_command_prints_file_cell_line_and_fails(tmp_path):
    (tmp_path / "benchmarks").mkdir()
    (tmp_path / "notebooks").mkdir()
    (tmp_path / "benchmarks" / "results.json").write_text(json.dumps(TOY))
    (tmp_path / "README.md").write_text("Intro.\n\nDP scores 0.945<!-- row: score -->.\n")
    cells = [{"cell_type": "code", "source": ["x = 0.5\n"]},
             {"cell_type": "markdown", "source": ["# Title\n", "\n", "It scores 0.931 here.\n"]}]
    (tmp_path / "notebooks" / "01_x.ipynb").write_text(json.dumps({"cells": cells}))
    run = subprocess.run([sys.executable, "-m", "benchmarks.check_text", "--root", str(tmp_path)],
                         cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 1, run.stderr
    assert run.stdout.splitlines() == ["notebooks/01_x.ipynb:1:3: '0.931' looks measured (a decimal) but names no row"]
    (tmp_path / "notebooks" / "01_x.ipynb").write_text(json.dumps({"cells": cells[:1]}))
    run = subprocess.run([sys.executable, "-m", "benchmarks.check_text", "--root", str(tmp_path)],
                         cwd=ROOT, capture_output=True, text=True)
    assert run.returncode == 0 and run.stdout == "", (run.stdout, run.stderr)
