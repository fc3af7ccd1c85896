"""Argument types for the commands: a bad number or device is refused by argparse, naming flag and value.

``argparse`` turns the ArgumentTypeError raised here into ``coursekit CMD: error: argument
--steps: must be an integer >= 1, got '0'`` (exit status 2) before any work starts. No flag ever
maps 0, a negative number, NaN or infinity to a silent default.
"""

from __future__ import annotations

import argparse
import math
import os
import re
from collections.abc import Callable
from pathlib import Path

MAX_SEED = 2**32 - 1
"""The environments' largest reset seed (numpy's legacy RandomState)."""


def int_in(lo: int | None = None, hi: int | None = None) -> Callable[[str], int]:
    """An argparse type: an integer in [lo, hi] (either bound may be None)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer{_range(lo, hi)}, got {text!r}") from None
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise argparse.ArgumentTypeError(f"must be an integer{_range(lo, hi)}, got {text!r}")
        return value
    parse.__name__ = "integer"
    return parse


def float_in(lo: float | None = None, hi: float | None = None, lo_open: bool = False) -> Callable[[str], float]:
    """An argparse type: a FINITE number in [lo, hi] ((lo, hi] with ``lo_open``)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        ok = math.isfinite(value) and (lo is None or value > lo or (value == lo and not lo_open)) and (hi is None or value <= hi)
        if not ok:
            raise argparse.ArgumentTypeError(f"must be a finite number{_range(lo, hi, lo_open)}, got {text!r}")
        return value
    parse.__name__ = "number"
    return parse


def _range(lo, hi, lo_open: bool = False) -> str:
    if lo is not None and hi is not None:
        return f" in {'(' if lo_open else '['}{_num(lo)}, {_num(hi)}]"
    if lo is not None:
        return f" {'>' if lo_open else '>='} {_num(lo)}"
    if hi is not None:
        return f" <= {_num(hi)}"
    return ""


def _num(value: float) -> str:
    """An integer bound in full (4294967295, not 4.29497e+09); a float one as short as it is exact."""
    return str(value) if isinstance(value, int) else f"{value:g}"


positive_int = int_in(1)
nonnegative_int = int_in(0)
seed_int = int_in(0, MAX_SEED)
positive_float = float_in(0.0, lo_open=True)
nonnegative_float = float_in(0.0)

_DEVICE = re.compile(r"auto|cpu|mps|cuda(:\d+)?")


def device(text: str) -> str:
    """An argparse type: auto, cpu, cuda, cuda:N or mps (availability is checked when the device is used)."""
    if not _DEVICE.fullmatch(text):
        raise argparse.ArgumentTypeError(f"must be auto, cpu, cuda, cuda:N or mps, got {text!r}")
    return text


def int_list_in(lo: int, hi: int, max_len: int) -> Callable[[str], tuple[int, ...]]:
    """An argparse type: 1 to ``max_len`` comma-separated integers, each in [lo, hi], e.g. 32,64,128."""
    def parse(text: str) -> tuple[int, ...]:
        try:
            values = tuple(int(v) for v in text.split(","))
        except ValueError:
            values = ()
        if not 1 <= len(values) <= max_len or any(not lo <= v <= hi for v in values):
            raise argparse.ArgumentTypeError(f"must be 1 to {max_len} comma-separated integers in [{lo}, {hi}] like "
                                             f"32,64,128, got {text!r}")
        return values
    parse.__name__ = "list of integers"
    return parse


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask where the OS has one, else all of them)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def threads(text: str) -> int:
    """An argparse type: torch CPU threads, 1 to the CPUs this process may use (more only slows it down)."""
    n = usable_cpus()
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= n:
        raise argparse.ArgumentTypeError(f"must be an integer in [1, {n}] (the CPUs this process may use), got {text!r}")
    return value


def output_path(text: str) -> Path:
    """An argparse type: a path to write to; '' (which would mean the current folder) is refused.

    Everything else about the path is checked by ``coursekit.outputs.check_output`` before any work.
    """
    if not text.strip():
        raise argparse.ArgumentTypeError(f"must name a file or folder to write, got {text!r}")
    return Path(text)
