"""Argument types for the commands: a bad number or device is refused by argparse, naming flag and value.

``argparse`` turns the ArgumentTypeError raised here into ``coursekit CMD: error: argument
--steps: must be an integer >= 1, got '0'`` (exit status 2) before any work starts. No flag ever
maps 0, a negative number, NaN or infinity to a silent default.
"""

from __future__ import annotations

import argparse
import math
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
        return f" in {'(' if lo_open else '['}{lo:g}, {hi:g}]"
    if lo is not None:
        return f" {'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f" <= {hi:g}"
    return ""


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


def positive_int_list(text: str) -> tuple[int, ...]:
    """An argparse type: comma-separated positive integers, e.g. 32,64,128."""
    try:
        values = tuple(int(v) for v in text.split(","))
    except ValueError:
        values = ()
    if not values or any(v < 1 for v in values):
        raise argparse.ArgumentTypeError(f"must be comma-separated positive integers like 32,64,128, got {text!r}")
    return values


def output_path(text: str) -> Path:
    """An argparse type: a path to write to; '' (which would mean the current folder) is refused.

    Everything else about the path is checked by ``coursekit.outputs.check_output`` before any work.
    """
    if not text.strip():
        raise argparse.ArgumentTypeError(f"must name a file or folder to write, got {text!r}")
    return Path(text)
