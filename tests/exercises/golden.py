"""Golden values: what the reference implementation (diffusers) returns on a graded test's seeded
inputs, stored in the test module itself between ``# BEGIN GOLDEN`` and ``# END GOLDEN``.

Why stored: importing diffusers takes seconds (it imports torch._dynamo), and ``coursekit.check``
must answer in a few. The test module's ``golden_values()`` computes them with diffusers; this
command writes them into the module, and tests/test_exercise_golden.py fails when the stored values
differ from what diffusers returns now. Regenerate (diffusers installed) with::

    python tests/exercises/golden.py
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
MODULES = ("test_ddim_step.py", "test_noise_loss.py")
"""The graded test modules with golden values."""
BEGIN, END = "# BEGIN GOLDEN", "# END GOLDEN"
PER_LINE = 6


def load(name: str):
    """The test module ``name`` (a file in this folder), imported by path."""
    spec = importlib.util.spec_from_file_location(f"golden_{Path(name).stem}", HERE / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _literal(v) -> str:
    """An int as is; a float to 9 significant digits (enough to restore any float32 exactly)."""
    return repr(v) if isinstance(v, int) else repr(float(f"{v:.9g}"))


def _numbers(values: list, indent: str) -> list[str]:
    rows = [values[i: i + PER_LINE] for i in range(0, len(values), PER_LINE)]
    return [indent + " ".join(f"{_literal(v)}," for v in row) for row in rows]


def render(golden: dict[str, dict[str, list]]) -> str:
    """The block for ``golden`` (name -> field -> flat list of numbers), as Python source."""
    lines = [f"{BEGIN}: written by `python tests/exercises/golden.py` from golden_values(); do not edit",
             "GOLDEN = {"]
    for name, fields in golden.items():
        lines.append(f"    {name!r}: {{")
        for field, values in fields.items():
            lines += [f"        {field!r}: [", *_numbers(list(values), " " * 12), "        ],"]
        lines.append("    },")
    return "\n".join(lines + ["}", END])


def rewrite(path: Path, block: str) -> bool:
    """Put ``block`` in place of the file's golden block; True if the file changed."""
    text = path.read_text()
    start, end = text.index(BEGIN), text.index(END) + len(END)
    new = text[:start] + block + text[end:]
    if new != text:
        path.write_text(new)
    return new != text


def main() -> int:
    for name in MODULES:
        changed = rewrite(HERE / name, render(load(name).golden_values()))
        print(f"{name}: {'rewritten' if changed else 'unchanged'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
