"""The hostile corpus (tests/grading_corpus/attacks/): every attack class of issue 12, each aimed at
ONE exercise while the same student's other exercise is honest, graded with `--jobs 2` next to
honest classmates. An attacker hands in two modules, the attacked one and an honest partner
(temporal_ensembling for the chunk_windows attacks, chunk_windows for the kl ones), and not the
class's third exercise: only three submissions then start torch (the kl test module and its worker
import it), which about halves the time of this corpus. With bubblewrap: the attacked exercise
scores its documented points, every other row is untouched, no row is lost, the grader finishes,
nothing outside the scratch area changes, no process is left and a worker's disk stays within its
cap. Without bubblewrap (forced with COURSEKIT_SANDBOX=none) the rows README's threat table marks as
contained then are graded the same way (the others would damage this machine, so they are not run)."""

from __future__ import annotations

import csv
import hashlib
import os
import re
import shutil
import time
from pathlib import Path

import pytest

from coursekit.grading import bubblewrap
from coursekit.grading.exercises import get_exercise, repo_root
from coursekit.grading.grade import grade_submissions
from coursekit.grading.sandbox import Limits

pytestmark = pytest.mark.slow  # 25 students, 2-3 exercises each: about a minute on 2 busy cores
ATTACKS = Path(__file__).parent / "grading_corpus" / "attacks"
EXERCISES = ["chunk_windows", "kl", "temporal_ensembling"]
PARTNER = {"chunk_windows": "temporal_ensembling", "kl": "chunk_windows"}
"""The honest module an attacker hands in beside the attacked one (numpy-only where possible)."""
LIMITS = Limits(timeout_s=60, test_timeout_s=15, memory_mb=1024, output_mb=8, disk_mb=32)
FULL = {e: get_exercise(e).max_points for e in EXERCISES}

# attack -> (points on its exercise, status, text in its feedback, contained without bwrap)
EXPECTED = {
    "pytest_runtest_noop": (0, "ok", "NotImplementedError", True),
    "channel_patch": (0, "ok", "NotImplementedError", True),
    "gc_nonce": (0, "protocol", "the worker sent a", True),  # its forged lines break only its own reply channel
    "force_pass_plugin": (0, "ok", "NotImplementedError", True),
    "assert_allclose_noop": (0, "ok", "expected (W, 16)", True),
    "torch_testing_patch": (0, "ok", "expected a scalar", True),
    "torch_allclose_true": (0, "ok", "expected a scalar", True),
    "ndarray_subclass": (0, "ok", "expected (W, 16)", True),
    "setprofile_swap": (0, "ok", "expected (W, 16)", True),
    "thread_swap": (0, "ok", "expected (W, 16)", True),
    "kill_grader": (0, "ok", "NotImplementedError: still here", False),
    "sigstop_grader": (0, "ok", "NotImplementedError: frozen?", False),
    "daemon": (0, "ok", "NotImplementedError", False),
    "edit_files": (0, "ok", "NotImplementedError", False),
    "rewrite_library": (0, "ok", "NotImplementedError", False),
    "scanner": (0, "ok", "NotImplementedError", False),
    "accomplice": (0, "ok", "NotImplementedError", False),
    "proc_forge": (0, None, "", False),
    "disk_fill": (0, "ok", "disk_fill wrote", False),
    "calls_reference": (0, "reference", "calls the reference implementation", True),
    "imports_solutions": (0, "reference", "calls the reference implementation", True),
    "reload_reference": (0, "reference", "calls the reference implementation", False),
}
HONEST = ["aa_honest", "mm_honest", "zz_honest"]


def _target(attack: str) -> str:
    return next(p.stem for p in (ATTACKS / attack).glob("*.py"))


def _submissions(tmp: Path, attacks) -> Path:
    subs = tmp / "submissions"
    solutions = repo_root() / "solutions"
    for name in list(attacks) + HONEST:
        folder = subs / name
        folder.mkdir(parents=True)
        if name in attacks:
            target = _target(name)
            shutil.copy(ATTACKS / name / f"{target}.py", folder)
            shutil.copy(solutions / f"{PARTNER[target]}.py", folder)
        else:
            for exercise in EXERCISES:
                shutil.copy(solutions / f"{exercise}.py", folder)
    return subs


def _fingerprint() -> dict[str, str]:
    root = repo_root()
    files = [p for d in ("coursekit", "tests", "solutions", "exercises") for p in (root / d).rglob("*")
             if p.is_file() and "__pycache__" not in p.parts]
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in files}


def _pwned(*folders: Path) -> list[str]:
    return [str(p) for folder in folders if folder.is_dir() for p in folder.glob("*coursekit_pwned*")]


def _leftovers(tag: str) -> list[int]:
    pids = []
    for pid in os.listdir("/proc"):
        if pid.isdigit():
            try:
                if f"COURSEKIT_WORKER={tag}".encode() in Path(f"/proc/{pid}/environ").read_bytes():
                    pids.append(int(pid))
            except OSError:
                pass
    return pids


def _grade(tmp: Path, attacks, mode: str):
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(bubblewrap.MODE_ENV, mode)
        before, home_before = _fingerprint(), set(os.listdir(Path.home()))
        out = tmp / "out"
        summary = grade_submissions(_submissions(tmp, attacks), out, EXERCISES, jobs=2, limits=LIMITS, progress=False)
    csv_bytes = (out / "grades.csv").read_bytes()
    deadline = time.monotonic() + 10
    while _leftovers(summary.tag) and time.monotonic() < deadline:
        time.sleep(0.2)
    left = _leftovers(summary.tag)
    time.sleep(3)  # a surviving daemon would rewrite grades.csv now
    return dict(summary=summary, out=out, csv=csv_bytes, left=left, changed=[p for p, h in _fingerprint().items()
                if before.get(p) != h], home=set(os.listdir(Path.home())) - home_before)


@pytest.fixture(scope="module")
def with_bwrap(tmp_path_factory):
    if bubblewrap.mode() != "bwrap" and os.environ.get(bubblewrap.MODE_ENV, "auto") != "none":
        pytest.skip("bubblewrap is not usable here (install the `bubblewrap` package)")
    return _grade(tmp_path_factory.mktemp("attacks"), EXPECTED, "bwrap")


def _check_rows(result, attacks):
    out, summary = result["out"], result["summary"]
    rows = {r["student"]: r for r in csv.DictReader(out.joinpath("grades.csv").open())}
    assert set(rows) == set(attacks) | set(HONEST), "a row was lost or added"
    for name in HONEST:
        assert all(float(rows[name][e]) == FULL[e] for e in EXERCISES), (name, rows[name])
    for name in attacks:
        points, status, text, _ = EXPECTED[name]
        target = _target(name)
        grade = {g.exercise.id: g for g in next(s for s in summary.students if s.student == name).grades}
        assert float(rows[name][target]) == points, (name, rows[name], grade[target].reason)
        if status is not None:
            assert grade[target].status == status, (name, grade[target].status, grade[target].reason)
        partner = PARTNER[target]
        assert float(rows[name][partner]) == FULL[partner], f"{name}: its honest {partner} was hurt: {rows[name]}"
        for other in set(EXERCISES) - {target, partner}:  # not handed in: a zero row, never run
            assert float(rows[name][other]) == 0 and grade[other].status == "missing", (name, other, grade[other].status)
        assert text in (out / name / "feedback.md").read_text(), f"{name}: {text!r} not in its feedback"


def test_bwrap_every_attack_scores_its_documented_row(with_bwrap):
    assert with_bwrap["summary"].mode == "bwrap"
    _check_rows(with_bwrap, EXPECTED)


def test_bwrap_nothing_outside_scratch_changed_and_nothing_left(with_bwrap):
    out = with_bwrap["out"]
    assert with_bwrap["changed"] == [], f"files of the repository changed: {with_bwrap['changed'][:5]}"
    assert not [h for h in with_bwrap["home"] if "coursekit_pwned" in h], with_bwrap["home"]
    assert _pwned(Path("/tmp"), Path.home(), out, out.parent) == []
    assert with_bwrap["left"] == [], "worker processes outlived the grader"
    assert (out / "grades.csv").read_bytes() == with_bwrap["csv"], "grades.csv changed after the grader finished"
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    assert files == sorted(["grades.csv"] + [f"{s}/{f}" for s in list(EXPECTED) + HONEST
                                             for f in ("feedback.md", "results.json")])
    assert with_bwrap["summary"].seconds < 600


def test_bwrap_disk_per_worker_within_its_cap(with_bwrap):
    text = (with_bwrap["out"] / "disk_fill" / "feedback.md").read_text()
    written = int(re.search(r"disk_fill wrote (\d+) bytes", text).group(1))
    assert 0 < written <= LIMITS.disk_mb * 2**20, f"wrote {written} bytes with a {LIMITS.disk_mb} MiB cap"


def test_without_bwrap_the_contained_rows_hold(tmp_path):
    contained = {k: v for k, v in EXPECTED.items() if v[3]}
    result = _grade(tmp_path, contained, "none")
    assert result["summary"].mode == "none"
    _check_rows(result, contained)
    assert result["left"] == [] and result["changed"] == []


def test_readme_threat_table_matches_this_corpus():
    readme = (repo_root() / "README.md").read_text()
    rows = dict(re.findall(r"^\| `([a-z_]+)` \|[^|]*\| yes \| (yes|no|partly)[^|]*\|", readme, re.M))
    assert set(rows) == set(EXPECTED), f"README threat table rows differ: {sorted(set(rows) ^ set(EXPECTED))}"
    for name, (_, _, _, without) in EXPECTED.items():
        assert (rows[name] == "yes") == without, f"README says {name} without bwrap: {rows[name]}"
