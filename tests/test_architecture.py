"""Architecture rules as code: the import layers of .importlinter, and no file over 400 lines."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MAX_LINES = 400


def test_import_layers_and_no_cycles():
    """`lint-imports` (import-linter, pinned in environment.txt) keeps every contract in .importlinter."""
    lint = Path(sys.executable).with_name("lint-imports")
    assert lint.is_file(), f"lint-imports not found beside {sys.executable}: pip install -r environment.txt"
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-6000:] + proc.stderr[-2000:]
    assert "0 broken" in proc.stdout


def test_no_library_file_exceeds_400_lines():
    long = {str(p.relative_to(ROOT)): n for p in sorted((ROOT / "coursekit").rglob("*.py"))
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES}
    assert not long, f"split these by concept (one concept per module, <= {MAX_LINES} lines): {long}"
