"""A training run a person can read: ``metrics.csv`` row by row and a ``loss.png`` that keeps up.

:class:`MetricsLog` is a trainer callback (:class:`coursekit.train.TrainCallback`, passed as
``train(..., callbacks=[log])``; ``coursekit train`` writes one beside every checkpoint): each
``on_log(record)`` appends one row

    step, loss, lr, samples_per_s, wall_s

to ``<run_dir>/metrics.csv`` (header once, flushed after every row, so a run killed half-way keeps
every row it logged) and re-draws ``<run_dir>/loss.png`` at most every ``plot_every_s`` seconds;
``close()`` draws the final figure. The figure is the log's live view, so it is drawn here (the
trainer's layer) rather than in :mod:`coursekit.viz`. It is written atomically (temporary file +
``os.replace``), so an image viewer open on it never sees half a PNG.

The log never takes over a file it did not create: if ``metrics.csv`` or ``loss.png`` already
exists in ``run_dir`` it refuses, naming the file (whether to clear a folder is the command's
decision, e.g. its ``--overwrite``). :func:`plot_metrics` draws any such CSV on its own.
"""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, TextIO

import numpy as np

if TYPE_CHECKING:
    from coursekit.output_lock import OutputLock

COLUMNS = ("step", "loss", "lr", "samples_per_s", "wall_s")
"""Columns of ``metrics.csv``: optimiser step, training loss, learning rate, throughput, seconds since start."""
METRICS_NAME = "metrics.csv"
"""File name of the table inside a run folder."""
LOSS_PLOT_NAME = "loss.png"
"""File name of the loss curve inside a run folder."""
FIG_SIZE_IN, DPI = (7.5, 5.2), 100
"""Size (inches) and resolution of loss.png: 750 x 520 pixels."""


def read_metrics(metrics_csv: str | Path) -> dict[str, np.ndarray]:
    """Columns of a metrics CSV as float arrays (N,) keyed by :data:`COLUMNS`.

    Raises FileNotFoundError when the file is missing and ValueError when its header is not
    :data:`COLUMNS` or a cell is not a number (the message names the file, line and value).
    """
    path = Path(metrics_csv)
    if not path.is_file():
        raise FileNotFoundError(f"no metrics CSV at {path}")
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows or tuple(rows[0]) != COLUMNS:
        raise ValueError(f"{path} must start with the header {','.join(COLUMNS)}; got {rows[0] if rows else 'an empty file'}")
    values = np.empty((len(rows) - 1, len(COLUMNS)))
    for i, row in enumerate(rows[1:]):
        if len(row) != len(COLUMNS):
            raise ValueError(f"{path} line {i + 2}: expected {len(COLUMNS)} values, got {row}")
        for j, cell in enumerate(row):
            try:
                values[i, j] = float(cell)
            except ValueError:
                raise ValueError(f"{path} line {i + 2}, column {COLUMNS[j]!r}: {cell!r} is not a number") from None
    return {name: values[:, j] for j, name in enumerate(COLUMNS)}


def _running_mean(x: np.ndarray, window: int) -> np.ndarray:
    """Trailing mean over ``window`` rows (N,) -> (N,); the first rows average what there is."""
    c = np.cumsum(np.insert(x, 0, 0.0))  # (N + 1,)
    n = np.arange(1, len(x) + 1)
    lo = np.maximum(n - window, 0)
    return (c[n] - c[lo]) / (n - lo)


def _duration(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "? s"
    return f"{seconds:.1f} s" if seconds < 120 else f"{seconds / 60:.1f} min" if seconds < 7200 else f"{seconds / 3600:.2f} h"


def _minor_label(value: float, _pos: int) -> str:
    """Label a log axis' minor tick only at 2 and 5 times a power of ten (fewer, readable labels)."""
    if not value > 0:
        return ""
    lead = round(value / 10 ** math.floor(math.log10(value)), 6)
    return f"{value:g}" if lead in (2.0, 5.0) else ""


def summary_title(metrics: Mapping[str, np.ndarray]) -> str:
    """"<total steps> steps in <wall time>, <mean samples/s> samples/s on average" of read metrics."""
    step, sps, wall = (metrics[k][np.isfinite(metrics[k])] for k in ("step", "samples_per_s", "wall_s"))
    total = int(step.max()) if len(step) else 0
    mean_sps = f"{sps.mean():.0f}" if len(sps) else "?"
    return f"{total} steps in {_duration(float(wall.max()) if len(wall) else math.nan)}, {mean_sps} samples/s on average"


def plot_metrics(metrics_csv: str | Path, out_png: str | Path, lock: OutputLock | None = None) -> Path:
    """Draw a metrics CSV (see :data:`COLUMNS`) to ``out_png``; return its path.

    Top panel: the loss against the step (log y when every loss is positive, else linear), the
    raw rows faint and a trailing mean over ~2 % of the rows bold. Bottom panel: the learning
    rate. Title: total steps, wall time and mean samples/s. Non-finite values (a diverged loss)
    are left out of the lines, and counted in the legend. Written atomically (under ``lock``, the
    caller's lock on the run folder, if given: see :func:`coursekit.atomic.atomic_path`).

    Raises ValueError when the CSV has no rows (nothing to draw), plus what :func:`read_metrics` raises.
    """
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter

    from coursekit.atomic import atomic_path

    path = Path(metrics_csv)
    m = read_metrics(path)
    n = len(m["step"])
    if n == 0:
        raise ValueError(f"{path} has a header but no rows: nothing to plot")
    step, loss, lr = m["step"], m["loss"], m["lr"]
    ok = np.isfinite(step) & np.isfinite(loss)
    fig = Figure(figsize=FIG_SIZE_IN, layout="constrained")
    ax_loss, ax_lr = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1])
    window = max(1, n // 50)
    label = "loss (each logged step)"
    if (~ok).sum():
        label += f"; {(~ok).sum()} non-finite left out"
    ax_loss.plot(step[ok], loss[ok], lw=0.8 if window > 1 else 1.5, alpha=0.35 if window > 1 else 1.0, color="tab:blue", label=label)
    if window > 1 and ok.sum() > 1:
        ax_loss.plot(step[ok], _running_mean(loss[ok], window), lw=2.0, color="tab:blue",
                     label=f"trailing mean of {window} rows")
    if ok.any() and np.all(loss[ok] > 0):
        ax_loss.set_yscale("log")
        ax_loss.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))  # 0.1, not 10^-1
        ax_loss.yaxis.set_minor_formatter(FuncFormatter(_minor_label))
    ax_loss.set_ylabel("training loss")
    ax_loss.grid(True, which="both", alpha=0.3)
    ax_loss.legend(loc="upper right", fontsize=8)
    ok_lr = np.isfinite(step) & np.isfinite(lr)
    ax_lr.plot(step[ok_lr], lr[ok_lr], color="tab:orange", lw=1.5)
    ax_lr.set_ylabel("learning rate")
    ax_lr.set_xlabel("optimiser step")
    ax_lr.grid(True, alpha=0.3)
    ax_lr.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
    fig.suptitle(summary_title(m), fontsize=11)
    out = Path(out_png)
    with atomic_path(out, suffix=".png", lock=lock) as tmp:
        fig.savefig(tmp, dpi=DPI, format="png")
    return out


class MetricsLog:
    """Append training records to ``run_dir/metrics.csv`` and keep ``run_dir/loss.png`` up to date.

    >>> with MetricsLog(run_dir) as log:               # doctest: +SKIP
    ...     train(policy, batches, config, callbacks=[log])  # each record: step, loss, lr, samples_per_s, wall_s

    Args:
        run_dir: the run folder (created if missing). It must not already hold ``metrics.csv``
            or ``loss.png``: the log only writes files it created.
        plot_every_s: least number of seconds between two re-draws of ``loss.png`` during the
            run (the first record draws at once; :meth:`close` always draws the final one).
        lock: the command's lock on the run folder (``coursekit.outputs.claim_output``), so the
            plot's temporaries are recorded there; None locks each re-draw on its own.
        resume_at: continue the log of an interrupted run whose training resumes at this step
            (``coursekit.train_state``): ``metrics.csv`` must exist with the trainer's header; its
            rows past ``resume_at`` (logged after the state was saved, about to be logged again)
            are dropped, so every step appears once.

    Raises FileExistsError naming the file when ``metrics.csv`` or ``loss.png`` exists (unless resuming).
    """

    def __init__(self, run_dir: str | Path, *, plot_every_s: float = 30.0, lock: OutputLock | None = None,
                 resume_at: int | None = None) -> None:
        if not (isinstance(plot_every_s, (int, float)) and plot_every_s >= 0 and math.isfinite(plot_every_s)):
            raise ValueError(f"plot_every_s must be a finite number of seconds >= 0, got {plot_every_s!r}")
        self.run_dir = Path(run_dir)
        if self.run_dir.exists() and not self.run_dir.is_dir():
            raise NotADirectoryError(f"run_dir {self.run_dir} exists and is not a folder")
        self.csv_path = self.run_dir / METRICS_NAME
        self.png_path = self.run_dir / LOSS_PLOT_NAME
        self.plot_every_s = float(plot_every_s)
        self.lock = lock
        self.rows = 0
        """Rows written so far."""
        self._last_plot = -math.inf  # monotonic time of the last draw
        if resume_at is not None:
            self._fh = self._reopen(int(resume_at))
            self._writer = csv.writer(self._fh)
            return
        if self.png_path.exists():
            raise FileExistsError(f"{self.png_path} already exists and was not written by this run's log; "
                                  "choose a new run folder (or let the command's --overwrite clear it)")
        self.run_dir.mkdir(parents=True, exist_ok=True)
        try:  # "x": created here or not at all (no race between the check and the open)
            self._fh = self.csv_path.open("x", newline="")
        except FileExistsError:
            raise FileExistsError(f"{self.csv_path} already exists and was not written by this run's log; "
                                  "choose a new run folder (or let the command's --overwrite clear it)") from None
        self._writer = csv.writer(self._fh)
        self._writer.writerow(COLUMNS)
        self._fh.flush()

    def _reopen(self, step: int) -> TextIO:
        """The interrupted run's metrics.csv cut back to rows at steps <= ``step``, open for appending."""
        from coursekit.atomic import atomic_write_text

        try:
            lines = self.csv_path.read_text(encoding="utf-8").splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise ValueError(f"cannot resume the log {self.csv_path}: {exc}") from exc
        if not lines or lines[0].strip() != ",".join(COLUMNS):
            raise ValueError(f"cannot resume the log {self.csv_path}: it lacks the trainer's header {','.join(COLUMNS)}")
        kept = [line for line in lines[1:] if line.split(",", 1)[0].isdigit() and int(line.split(",", 1)[0]) <= step]
        atomic_write_text(self.csv_path, "\n".join([lines[0], *kept]) + "\n", lock=self.lock)
        self.rows = len(kept)
        return self.csv_path.open("a", newline="")

    @property
    def closed(self) -> bool:
        """True once :meth:`close` ran."""
        return self._fh.closed

    def on_log(self, record: Mapping[str, float]) -> None:
        """Append one record (keys exactly :data:`COLUMNS`) and re-draw the plot if it is due.

        Values are written as given (a NaN loss is logged, not refused: it is what happened);
        they must be numbers. Raises ValueError naming missing, unknown or non-numeric keys.
        """
        if self.closed:
            raise RuntimeError(f"this MetricsLog is closed; {self.csv_path} is complete")
        keys = set(record)
        if keys != set(COLUMNS):
            missing, extra = sorted(set(COLUMNS) - keys), sorted(keys - set(COLUMNS))
            raise ValueError(f"a metrics record needs exactly the keys {list(COLUMNS)}; "
                             f"missing {missing}, unknown {extra} in {dict(record)!r}")
        row = []
        for name in COLUMNS:
            value = record[name]
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise ValueError(f"metrics record {name!r} must be a number, got {value!r} ({type(value).__name__})")
            row.append(int(value) if name == "step" else repr(float(value)))
        self._writer.writerow(row)
        self._fh.flush()  # a killed run keeps every row logged so far
        self.rows += 1
        now = time.monotonic()
        if now - self._last_plot >= self.plot_every_s:
            plot_metrics(self.csv_path, self.png_path, lock=self.lock)
            self._last_plot = time.monotonic()

    def close(self) -> None:
        """Close the CSV and draw the final ``loss.png`` (none when no row was logged). Safe twice."""
        if self.closed:
            return
        self._fh.close()
        if self.rows:
            plot_metrics(self.csv_path, self.png_path, lock=self.lock)

    def __enter__(self) -> MetricsLog:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
