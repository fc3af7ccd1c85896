"""A run folder a person can read: metrics.csv holds exactly what was logged, loss.png is a real
figure, redrawn on schedule and atomically, and no file the log did not create is ever touched."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from PIL import Image

from coursekit.training_log import COLUMNS, DPI, FIG_SIZE_IN, MetricsLog, plot_metrics, read_metrics, summary_title


def records(n: int, start: int = 1) -> list[dict[str, float]]:
    """A plausible run: a decaying loss, a cosine learning rate, a noisy throughput."""
    rng = np.random.default_rng(0)
    out = []
    for i in range(start, start + n):
        out.append({"step": i, "loss": float(2.0 * math.exp(-i / 15) + 0.05 * rng.random()),
                    "lr": float(1e-4 * 0.5 * (1 + math.cos(math.pi * i / (start + n)))),
                    "samples_per_s": float(800 + 50 * rng.standard_normal()), "wall_s": 0.25 * i})
    return out


def rgb(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.float64)


def colour_fraction(img: np.ndarray, hex_colour: str, tol: float = 30.0) -> float:
    target = np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)], dtype=np.float64)
    return float((np.linalg.norm(img - target, axis=-1) < tol).mean())


def assert_real_figure(path) -> None:
    img = rgb(path)
    assert img.shape == (round(FIG_SIZE_IN[1] * DPI), round(FIG_SIZE_IN[0] * DPI), 3)
    assert img.std() > 10, "the figure is (nearly) uniform"
    assert colour_fraction(img, "#1f77b4") > 0.001, "no loss line (tab:blue) drawn"
    assert colour_fraction(img, "#ff7f0e") > 0.0005, "no learning-rate line (tab:orange) drawn"


def test_csv_rows_equal_what_was_logged(tmp_path):
    logged = records(40)
    with MetricsLog(tmp_path / "run", plot_every_s=3600) as log:
        for r in logged:
            log.on_log(r)
        # flushed row by row: a reader (or a run killed now) already sees every row
        with (tmp_path / "run" / "metrics.csv").open(newline="") as fh:
            assert len(list(csv.reader(fh))) == 1 + len(logged)
    with (tmp_path / "run" / "metrics.csv").open(newline="") as fh:
        rows = list(csv.reader(fh))
    assert tuple(rows[0]) == COLUMNS == ("step", "loss", "lr", "samples_per_s", "wall_s")
    assert len(rows) == 1 + len(logged)
    for row, want in zip(rows[1:], logged):
        assert [float(v) for v in row] == [float(want[k]) for k in COLUMNS]  # exact: repr round-trips
    m = read_metrics(tmp_path / "run" / "metrics.csv")
    np.testing.assert_array_equal(m["loss"], [r["loss"] for r in logged])
    assert_real_figure(tmp_path / "run" / "loss.png")


def test_plot_is_redrawn_on_schedule_and_atomically(tmp_path):
    png = tmp_path / "loss.png"
    log = MetricsLog(tmp_path, plot_every_s=3600)
    first, second = records(2)
    log.on_log(first)  # the first record draws at once
    inode = png.stat().st_ino
    log.on_log(second)  # an hour has not passed: no redraw
    assert png.stat().st_ino == inode
    log.close()  # the final figure: a new file renamed over the old one (atomic replace)
    assert png.stat().st_ino != inode
    assert not list(tmp_path.glob(".*.tmp*")), "a temporary file was left behind"
    log.close()  # twice is fine
    with pytest.raises(RuntimeError, match="closed"):
        log.on_log(second)

    every = MetricsLog(tmp_path / "every", plot_every_s=0)
    every.on_log(first)
    inode = (tmp_path / "every" / "loss.png").stat().st_ino
    every.on_log(second)
    assert (tmp_path / "every" / "loss.png").stat().st_ino != inode
    every.close()


@pytest.mark.parametrize("name", ["metrics.csv", "loss.png"])
def test_refuses_a_file_it_did_not_create(tmp_path, name):
    foreign = tmp_path / name
    foreign.write_text("someone else's file\n")
    with pytest.raises(FileExistsError, match=name):
        MetricsLog(tmp_path)
    assert foreign.read_text() == "someone else's file\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


def test_a_second_log_in_the_same_folder_is_refused(tmp_path):
    with MetricsLog(tmp_path) as log:
        log.on_log(records(1)[0])
    before = (tmp_path / "metrics.csv").read_bytes()
    with pytest.raises(FileExistsError, match="metrics.csv|loss.png"):
        MetricsLog(tmp_path)
    assert (tmp_path / "metrics.csv").read_bytes() == before


def test_bad_records_are_refused_and_not_written(tmp_path):
    with MetricsLog(tmp_path, plot_every_s=3600) as log:
        good = records(1)[0]
        with pytest.raises(ValueError, match="missing \\['lr'\\]"):
            log.on_log({k: v for k, v in good.items() if k != "lr"})
        with pytest.raises(ValueError, match="unknown \\['grad_norm'\\]"):
            log.on_log({**good, "grad_norm": 1.0})
        with pytest.raises(ValueError, match="'loss' must be a number, got 'low'"):
            log.on_log({**good, "loss": "low"})
        assert log.rows == 0
        log.on_log({**good, "loss": float("nan")})  # a diverged loss is logged, not refused
    rows = (tmp_path / "metrics.csv").read_text().splitlines()
    assert rows[0] == ",".join(COLUMNS) and len(rows) == 2 and rows[1].split(",")[1] == "nan"
    with pytest.raises(ValueError, match="plot_every_s"):
        MetricsLog(tmp_path / "other", plot_every_s=-1)


def test_no_rows_no_figure(tmp_path):
    MetricsLog(tmp_path).close()
    assert (tmp_path / "metrics.csv").read_text().strip() == ",".join(COLUMNS)
    assert not (tmp_path / "loss.png").exists()
    with pytest.raises(ValueError, match="no rows"):
        plot_metrics(tmp_path / "metrics.csv", tmp_path / "loss.png")


def test_plot_metrics_on_a_hand_written_csv(tmp_path):
    path = tmp_path / "hand.csv"
    path.write_text("step,loss,lr,samples_per_s,wall_s\n"
                    "10,1.5,1e-4,100,2.0\n"
                    "20,0.9,1e-4,300,4.0\n"
                    "30,0.4,5e-5,200,150.0\n")
    m = read_metrics(path)
    np.testing.assert_array_equal(m["step"], [10, 20, 30])
    np.testing.assert_array_equal(m["lr"], [1e-4, 1e-4, 5e-5])
    assert summary_title(m) == "30 steps in 2.5 min, 200 samples/s on average"
    out = plot_metrics(path, tmp_path / "figs" / "hand.png")
    assert out == tmp_path / "figs" / "hand.png"
    assert_real_figure(out)
    # a loss that is not positive everywhere (a linear axis) and a diverged row still draw
    path.write_text(path.read_text() + "40,-0.2,5e-5,200,151.0\n50,nan,5e-5,200,152.0\n")
    assert_real_figure(plot_metrics(path, tmp_path / "neg.png"))


def test_plot_metrics_names_a_bad_csv(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothing.csv"):
        plot_metrics(tmp_path / "nothing.csv", tmp_path / "x.png")
    bad = tmp_path / "bad.csv"
    bad.write_text("step,loss\n1,2\n")
    with pytest.raises(ValueError, match="bad.csv must start with the header"):
        plot_metrics(bad, tmp_path / "x.png")
    bad.write_text("step,loss,lr,samples_per_s,wall_s\n1,oops,1e-4,1,1\n")
    with pytest.raises(ValueError, match="line 2, column 'loss': 'oops'"):
        plot_metrics(bad, tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()
