"""Golden episodes of every shipped checkpoint, for tests/test_shipped_checkpoints.py.

Run: ``.venv/bin/python -m benchmarks.shipped_golden`` (about 3 minutes on one thread). For each
checkpoint in ``coursekit/checkpoints/`` it runs the command a student uses,
``coursekit eval CKPT --episodes 12 --threads 1 --json ...`` (held-out seeds 100000-100011, the
checkpoint's own sampler and executor), and stores each episode's score, success and steps with
the weights' sha256 and a fingerprint of the machine (torch version, CPU) in
``tests/golden/shipped_episodes.json``. The test re-runs the same command in ``make test`` and
compares episode by episode: a stale checkpoint, a changed sampler or executor, or a changed
environment changes episodes even where a mean would hide it; twelve episodes keep the run short
(about a quarter of a 50-episode reproduction). The quality figures of these checkpoints are
their rows in ``benchmarks/results.json``, measured on more seeds by their own benchmarks.
Regenerate after retraining a checkpoint (the test says when: the weights' sha256 differs).
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "coursekit" / "checkpoints"
GOLDEN = ROOT / "tests" / "golden" / "shipped_episodes.json"
EPISODES = 12
EVAL_ARGS = ["--episodes", str(EPISODES), "--threads", "1", "--no-progress"]
"""`coursekit eval` flags of the golden run and of the test (after the checkpoint, before --json)."""
GOLDEN_FORMAT = "coursekit-shipped-golden"


def fingerprint() -> dict[str, str]:
    """What a network's rounding depends on: torch's version and build, and the CPU."""
    import torch

    from benchmarks.results import cpu_model

    return {"torch": torch.__version__, "cpu": cpu_model(), "python": platform.python_version()}


def weights_sha256(checkpoint: Path) -> str:
    from coursekit.checkpoint import WEIGHTS_FILE
    from coursekit.weights_file import file_sha256

    return file_sha256(checkpoint / WEIGHTS_FILE)


def shipped() -> list[Path]:
    return sorted(p for p in SHIPPED.iterdir() if (p / "config.json").is_file())


def eval_episodes(checkpoint: Path, scratch: Path) -> dict:
    """The `coursekit eval --json` summary of the golden protocol on ``checkpoint``."""
    import torch

    from coursekit.cli import main as cli_main

    out = scratch / f"{checkpoint.name}.json"
    threads = torch.get_num_threads()
    try:
        rc = cli_main(["eval", str(checkpoint), *EVAL_ARGS, "--json", str(out)])
    finally:
        torch.set_num_threads(threads)  # --threads sets it process-wide
    if rc != 0:
        raise RuntimeError(f"coursekit eval {checkpoint} exited with {rc}")
    return json.loads(out.read_text())


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=GOLDEN, help=f"golden file (default {GOLDEN.relative_to(ROOT)})")
    args = parser.parse_args(argv)
    if args.out.exists() and (not args.out.is_file() or json.loads(args.out.read_text()).get("format") != GOLDEN_FORMAT):
        raise SystemExit(f"{args.out} exists and is not a golden file this command wrote: refusing to replace it")
    from coursekit.atomic import atomic_write_text

    golden = {"format": GOLDEN_FORMAT, "command": ".venv/bin/python -m benchmarks.shipped_golden",
              "eval_args": EVAL_ARGS, "fingerprint": fingerprint(), "measured": time.strftime("%Y-%m-%d"),
              "checkpoints": {}}
    with tempfile.TemporaryDirectory(prefix="coursekit-golden-") as tmp:
        for checkpoint in shipped():
            t0 = time.perf_counter()
            summary = eval_episodes(checkpoint, Path(tmp))
            golden["checkpoints"][checkpoint.name] = {
                "weights_sha256": weights_sha256(checkpoint), "per_episode": summary["per_episode"],
                "score": summary["score"], "success_rate": summary["success_rate"],
                **({"strict_success_rate": summary["strict_success_rate"]} if "strict_success_rate" in summary else {})}
            print(f"{checkpoint.name:24s} score {summary['score']:.3f}, success {summary['success_rate']:.0%} "
                  f"({time.perf_counter() - t0:.0f} s)")
    atomic_write_text(args.out, json.dumps(golden, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
