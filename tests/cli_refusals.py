"""The bad-input suites' one assertion: a refused command line is ONE clear error line and touches nothing.

Only the tests use this module (``from cli_refusals import ...``: pytest puts tests/ on the path).
"""

from __future__ import annotations

from pathlib import Path


def tree_snapshot(root: Path) -> dict[str, bytes | None]:
    """Every entry below ``root``: its bytes (files) or None (folders), to prove a command changed nothing."""
    return {str(p.relative_to(root)): (p.read_bytes() if p.is_file() else None) for p in sorted(root.rglob("*"))}


def assert_refused_in_one_line(main, argv: list[str], area: Path, expected: str, capsys) -> None:
    """``main(argv)`` exits 2 with ONE stderr line 'coursekit CMD: error: ...' containing ``expected`` (with
    {A} = ``area``), no traceback, and every entry below ``area`` exactly as it was."""
    before = tree_snapshot(area)
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.count("\n") == 1 and err.endswith("\n"), f"not one line:\n{err}"
    assert err.startswith(f"coursekit {argv[0]}") and ": error: " in err, err
    assert "Traceback" not in err
    assert expected.replace("{A}", str(area)) in err, err
    assert tree_snapshot(area) == before, "a pre-existing file changed, or something was written"
