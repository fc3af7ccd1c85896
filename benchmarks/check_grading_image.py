"""The autograder image, built for real: a fresh venv from requirements-grading.txt alone grades (not CI).

Run: ``.venv/bin/python -m benchmarks.check_grading_image [--extra-index-url URL]``

1. Writes the Gradescope zip (every exercise) and unpacks it as ``/autograder/source`` would be.
2. Makes a fresh venv and times what the zip's setup.sh does to it: ``pip install --no-deps -r
   requirements-grading.txt`` (the zip's copy) and ``pip check``. setup.sh adds PyTorch's CPU index
   (``--extra-index-url https://download.pytorch.org/whl/cpu``) for ``torch==...+cpu``; where that
   index is not reachable (this machine), pass nothing and torch's CPU wheel comes from the
   machine's own pip configuration. pip's cache is used as usual.
3. Runs the zip's ``run_autograder`` with that venv's python on the worked solutions (every test
   must pass: full marks) and on the untouched stubs (zero, every test failing on its exercise's
   NotImplementedError, none on a missing module).
4. Records the install time, the venv's size and the verdict in ``benchmarks/results.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import venv
import zipfile
from pathlib import Path

from benchmarks.results import record
from coursekit.grading.exercises import EXERCISES, repo_root
from coursekit.grading.gradescope import IMAGE, write_autograder
from coursekit.grading.gradescope import REQUIREMENTS_FILE

COMMAND = ".venv/bin/python -m benchmarks.check_grading_image"
SECTION = "Grading"


def pip(python: Path, *args: str) -> str:
    """Run ``python -m pip args``; RuntimeError with pip's last words when it fails."""
    res = subprocess.run([str(python), "-m", "pip", *args], capture_output=True, text=True)
    if res.returncode:
        raise RuntimeError(f"pip {' '.join(args)} failed: {(res.stdout + res.stderr).strip()[-2000:]}")
    return res.stdout


def folder_mb(path: Path) -> float:
    """Bytes of the files under ``path`` (links not followed), in MB."""
    return sum(p.lstat().st_size for p in path.rglob("*") if p.is_file() and not p.is_symlink()) / 1e6


def build_image(home: Path, source: Path, extra_index: str | None) -> tuple[Path, float, float]:
    """(venv python, seconds to create the venv, seconds for setup.sh's pip install + pip check)."""
    start = time.perf_counter()
    venv.create(home, with_pip=True, symlinks=True)
    created = time.perf_counter() - start
    python = home / "bin" / "python"
    index = ["--extra-index-url", extra_index] if extra_index else []
    start = time.perf_counter()
    pip(python, "install", "-q", "--no-deps", *index, "-r", str(source / REQUIREMENTS_FILE))
    pip(python, "check")
    return python, created, time.perf_counter() - start


def grade(tree: Path, python: Path, folder: Path) -> dict:
    """run_autograder on a submission holding ``folder``'s exercise modules; its results.json."""
    shutil.rmtree(tree / "submission", ignore_errors=True)
    shutil.rmtree(tree / "results", ignore_errors=True)
    (tree / "submission").mkdir()
    for e in EXERCISES:
        shutil.copy(folder / f"{e.id}.py", tree / "submission" / f"{e.id}.py")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "COURSEKIT_EXERCISES")}
    env.update(AUTOGRADER_ROOT=str(tree), COURSEKIT_PYTHON=str(python))
    res = subprocess.run(["bash", str(tree / "source" / "run_autograder")], env=env, capture_output=True, text=True)
    if res.returncode:
        raise RuntimeError(f"run_autograder failed: {(res.stdout + res.stderr).strip()[-3000:]}")
    return json.loads((tree / "results" / "results.json").read_text())


def verdict(solutions: dict, stubs: dict) -> list[str]:
    """What is wrong with the two gradings (empty: full marks and zero, as they should be)."""
    problems = []
    full = sum(t["max_score"] for t in solutions["tests"])
    if solutions["score"] != full or any(t["status"] != "passed" for t in solutions["tests"]):
        failed = [t["name"] for t in solutions["tests"] if t["status"] != "passed"]
        problems.append(f"solutions scored {solutions['score']} / {full}; failed: {failed[:5]}")
    if stubs["score"] != 0 or any(t["status"] != "failed" for t in stubs["tests"]):
        problems.append(f"stubs scored {stubs['score']}")
    odd = [t["name"] for t in stubs["tests"] if "NotImplementedError: Exercise" not in t["output"]
           or "No module named" in t["output"]]
    if odd:
        problems.append(f"stub tests failing for another reason than the stub: {odd[:5]}")
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--extra-index-url", default=None,
                        help="PyTorch's CPU index as setup.sh uses it (https://download.pytorch.org/whl/cpu), "
                             "where reachable; default: this machine's pip configuration")
    args = parser.parse_args(argv)
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="coursekit-grading-image-") as tmp:
        tree = Path(tmp) / "autograder"
        zip_path = write_autograder(Path(tmp) / "autograder.zip")
        zipfile.ZipFile(zip_path).extractall(tree / "source")
        try:
            python, created, installed = build_image(Path(tmp) / "venv", tree / "source", args.extra_index_url)
        except RuntimeError as exc:
            print(f"cannot build the grading venv: {exc}", file=sys.stderr)
            return 2
        packages = pip(python, "list", "--format=freeze").split()
        size = folder_mb(Path(tmp) / "venv")
        version = subprocess.run([str(python), "-c", "import sys; print(sys.version.split()[0])"], capture_output=True,
                                 text=True).stdout.strip()
        start = time.perf_counter()
        solutions = grade(tree, python, repo_root() / "solutions")
        stubs = grade(tree, python, repo_root() / "exercises")
        graded = time.perf_counter() - start
    problems = verdict(solutions, stubs)
    full = sum(t["max_score"] for t in solutions["tests"])
    isolation = "no OS isolation" if "without OS isolation" in solutions["output"] else "bubblewrap"
    source = f"extra index {args.extra_index_url}" if args.extra_index_url else \
        "torch's CPU wheel from this machine's pip configuration (PyTorch's CPU index, which setup.sh adds, is not reachable here)"
    note = (f"python -m venv (Python {version}; the zip targets {IMAGE['os']}, Python {IMAGE['python']}) in {created:.1f} s, "
            f"then pip install --no-deps -r {REQUIREMENTS_FILE} + pip check in {installed:.0f} s, pip's cache in use; "
            f"{source}; 1-min load average {load:.1f} on {os.cpu_count()} cores; "
            f"{len(packages)} packages: {', '.join(packages)}")
    print(note)
    record(SECTION, "autograder image: fresh venv + pip install of requirements-grading.txt", round(created + installed, 1),
           "s", COMMAND, target="< 120 s", note=note)
    record(SECTION, "autograder image: venv size", round(size), "MB", COMMAND,
           note=f"{len(packages)} packages, {next((p for p in packages if p.startswith('torch==')), 'no torch')}")
    grading = (f"solutions {solutions['score']:g} / {full:g}, stubs {stubs['score']:g} / {full:g}, "
               f"{len(solutions['tests'])} tests x 2 in {graded:.0f} s ({isolation}) by run_autograder in that venv")
    print(grading, *problems, sep="\n")
    record(SECTION, "autograder image grades solutions to full marks, stubs to zero", "pass" if not problems else "fail",
           "", COMMAND, target="pass", note=grading + ("; " + " | ".join(problems) if problems else ""))
    return 0 if not problems else 1


if __name__ == "__main__":
    raise SystemExit(main())
