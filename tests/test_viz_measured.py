"""coursekit.viz.measured reads the results table's rows into figure series, intervals included."""

from __future__ import annotations

import json

import matplotlib
import pytest

matplotlib.use("Agg")

from coursekit.viz.measured import (  # noqa: E402
    DATA_SETS, PIXEL_ROUTES, SHIPPED_ROWS, budget_curve, by_data_set, chunk_sweep, chunk_sweep_seeds,
    leads_by_data_set, load_rows, per_seed, plot_points, side_by_side)


def row(section, name, value, interval=None, n=None, unit=""):
    return {"section": section, "name": name, "value": value, "interval": interval, "n": n, "unit": unit}


ROWS = {
    "a": row("Chunk ablation (PushT)", "Diffusion Policy DDIM-10 (To=2, Tp=16, Ta=8) score, 3 training seed(s), 6000 steps",
             0.79, [0.78, 0.80], 600),
    "b": row("Chunk ablation (PushT)", "Diffusion Policy DDIM-10 (To=2, Tp=16, Ta=8) score, 3 training seed(s), 2000 steps",
             0.35, [0.32, 0.38], 600),
    "c": row("Chunk ablation (PushT)", "Diffusion Policy DDIM-10 (To=2, Tp=16, Ta=8) score, 3 training seed(s), "
             "2000 steps, two-way starts", 0.29, [0.21, 0.37], 234),
    "d": row("Chunk ablation (PushT)", "chunked regression (To=2, Tp=16, Ta=8) score, 3 training seed(s)", 0.78,
             [0.72, 0.84], 600),  # no budget in the name: not a point of the curve
    "e": row("Chunk ablation (arm pair)", "ACT k=10, open-loop chunks (Ta=k): strict success", 80.0, [76.6, 83.0], 600, "%"),
    "f": row("Chunk ablation (arm pair)", "ACT k=1, open-loop chunks (Ta=k): strict success", 10.0, [7.9, 12.6], 600, "%"),
    "g": row("Chunk ablation (arm pair)", "ACT k=100 without CVAE, open-loop chunks (Ta=k): strict success", 85.0,
             [82.0, 87.6], 600, "%"),
}


def test_budget_curve_takes_the_all_starts_rows_with_a_budget_sorted_by_steps():
    assert budget_curve(ROWS) == {"Diffusion Policy DDIM-10": [(2000, 0.35, 0.32, 0.38, 600), (6000, 0.79, 0.78, 0.80, 600)]}


def test_by_data_set_pairs_each_head_across_the_two_demonstration_sets_at_one_budget():
    rows = {**ROWS,
            "p": row("Chunk ablation (PushT)", "Diffusion Policy DDIM-10 (To=2, Tp=16, Ta=8) score, 3 training seed(s), "
                     "6000 steps, person-like demonstrations", 0.70, [0.65, 0.75], 600),
            "q": row("Chunk ablation (PushT)", "single-step regression (To=1, Tp=Ta=1) score, 3 training seed(s), "
                     "6000 steps, person-like demonstrations, two-way starts", 0.5, [0.4, 0.6], 234)}  # a subset: not a point
    assert DATA_SETS == ("scripted planner", "person-like")
    assert by_data_set(rows) == {"Diffusion Policy DDIM-10": [(0, 0.79, 0.78, 0.80, 600), (1, 0.70, 0.65, 0.75, 600)]}
    assert by_data_set(rows, steps=2000) == {"Diffusion Policy DDIM-10": [(0, 0.35, 0.32, 0.38, 600)]}


def test_leads_by_data_set_pairs_dps_lead_per_regressor_and_kind_of_start_across_the_sets():
    name = "DP DDIM-10 minus single-step regression, 3 training seed(s), {steps} steps{person}, {starts} starts"
    rows = {str(i): row("Chunk ablation (PushT)", name.format(steps=steps, person=person, starts=starts), value,
                        [value - 0.1, value + 0.1], 234)
            for i, (steps, person, starts, value) in enumerate([
                (6000, "", "two-way", -0.04), (6000, ", person-like demonstrations", "two-way", 0.10),
                (6000, ", person-like demonstrations", "other", 0.01), (20000, "", "two-way", 0.09),
                (6000, ", person-like demonstrations", "all", 0.05)])}  # all starts and another budget: not here
    assert leads_by_data_set(rows) == {
        "minus single-step regression, other starts": [pytest.approx((1, 0.01, -0.09, 0.11, 234))],
        "minus single-step regression, two-way starts": [pytest.approx((0, -0.04, -0.14, 0.06, 234)),
                                                         pytest.approx((1, 0.10, 0.0, 0.2, 234))]}


def test_chunk_sweep_in_fractions_with_the_no_cvae_point_apart():
    sweep, no_vae = chunk_sweep(ROWS)
    assert list(sweep) == ["open-loop chunks (Ta=k)"] and list(no_vae) == ["open-loop chunks (Ta=k)"]
    assert sweep["open-loop chunks (Ta=k)"] == [pytest.approx((1, 0.10, 0.079, 0.126, 600)),
                                                pytest.approx((10, 0.80, 0.766, 0.83, 600))]
    assert no_vae["open-loop chunks (Ta=k)"] == pytest.approx((100, 0.85, 0.82, 0.876, 600))


def test_chunk_sweep_keeps_each_task_apart_and_skips_the_camera_run():
    on_insertion = {
        "i": row("Chunk ablation (arm pair)", "ACT k=10 on insertion, open-loop chunks (Ta=k): strict success", 4.8,
                 [3.4, 6.9], 600, "%"),
        "j": row("Chunk ablation (arm pair)", "ACT k=100 without CVAE on insertion, open-loop chunks (Ta=k): strict "
                 "success", 50.0, [46.0, 54.0], 600, "%"),
        "c": row("Chunk ablation (arm pair)", "ACT k=100 from the top camera, open-loop chunks (Ta=k): strict success",
                 94.5, [90.4, 96.9], 200, "%"),
    }
    rows = {**ROWS, **on_insertion}
    rows["i"]["note"] = "training seeds [0, 1, 2] (per seed: 4.0 %, 6.0 %, 4.5 %; ...)"
    assert chunk_sweep(rows) == chunk_sweep(ROWS)  # the transfer cube's, as before
    sweep, no_vae = chunk_sweep(rows, "insertion")
    assert sweep == {"open-loop chunks (Ta=k)": [pytest.approx((10, 0.048, 0.034, 0.069, 600))]}
    assert no_vae == {"open-loop chunks (Ta=k)": pytest.approx((100, 0.50, 0.46, 0.54, 600))}
    assert chunk_sweep_seeds(rows, "insertion") == {
        ("open-loop chunks (Ta=k)", False): [(10, pytest.approx([0.04, 0.06, 0.045]))]}
    assert chunk_sweep(rows, "no_such_task") == ({}, {})


def test_chunk_sweep_seeds_reads_each_training_seed_from_the_note_as_it_is_written():
    rows = {**ROWS}
    rows["e"] = {**ROWS["e"], "note": "training seeds [0, 1, 2] (per seed: 40.0 %, 16.5 %, 16.5 %; t-interval over "
                                      "seeds [-9.4, 58.0] %); 200 protocol seeds each"}
    rows["g"] = {**ROWS["g"], "note": "training seeds [0] (per seed: 85.0 %; t-interval ...)"}
    assert chunk_sweep_seeds(rows) == {
        ("open-loop chunks (Ta=k)", False): [(10, pytest.approx([0.40, 0.165, 0.165]))],  # k = 1 has no note: no dots
        ("open-loop chunks (Ta=k)", True): [(100, pytest.approx([0.85]))]}
    pushT = {"note": "mean over training seeds [0, 1, 2] (per seed: 0.702, -0.633, 0.801; sd 0.084)"}
    assert per_seed(pushT) == [0.702, -0.633, 0.801] and per_seed({"note": "no seeds here"}) == []


def test_load_rows_filters_a_section_and_is_empty_without_a_table(tmp_path):
    path = tmp_path / "results.json"
    path.write_text(json.dumps(ROWS))
    assert set(load_rows("Chunk ablation (arm pair)", path)) == {"e", "f", "g"}
    assert load_rows(None, tmp_path / "absent.json") == {}


def test_plot_points_draws_the_interval_and_names_a_thin_n():
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    plot_points(ax, [(1, 0.5, 0.4, 0.7, 50), (2, 0.6, 0.55, 0.65, 200)], "x")
    (container,) = ax.containers
    lo, hi = container.lines[1][0].get_ydata(), container.lines[1][1].get_ydata()  # the cap markers
    assert list(lo) == [0.4, 0.55] and list(hi) == [0.7, 0.65]
    assert ax.get_legend_handles_labels()[1] == ["x (n = 50-50 on some points)"]
    plt.close(fig)


def test_side_by_side_reads_each_shipped_row_as_a_fraction_and_skips_missing_ones():
    pusht, cube = list(SHIPPED_ROWS)[:2]
    dp_key, cube_key = SHIPPED_ROWS[pusht][0][1], SHIPPED_ROWS[cube][1][1]
    rows = {dp_key: row("Diffusion Policy", "x", 0.945, [0.912, 0.974], 200),
            cube_key: row("ACT", "y", 96.5, [93.0, 98.3], 200, "%")}
    got = side_by_side(rows)
    assert got[pusht] == [("Diffusion Policy, DDIM-10", 0.945, 0.912, 0.974, 200)]
    head, value, lo, hi, n = got[cube][0]
    assert head == "ACT, ensembling" and n == 200
    assert (value, lo, hi) == pytest.approx((0.965, 0.93, 0.983))
    assert side_by_side({}) == {}


def test_every_shipped_row_the_figure_names_is_in_the_table():
    from pathlib import Path

    table = load_rows(path=Path(__file__).resolve().parent.parent / "benchmarks" / "results.json")
    missing = [key for heads in SHIPPED_ROWS.values() for _, key in heads if key not in table]
    assert not missing, f"chapter 9's figure names rows the table lacks: {missing}"
    assert all(table[key]["n"] >= 200 and table[key]["interval"] for heads in SHIPPED_ROWS.values() for _, key in heads)


def test_the_pixel_figure_names_the_rows_bench_pixel_policy_writes_and_the_keypoint_row_exists():
    from pathlib import Path

    from benchmarks.bench_pixel_policy import SECTION, score_row

    (task, heads), = PIXEL_ROUTES.items()
    keys = [key for _, key in heads]
    assert keys[1:] == [f"{SECTION}/{score_row('two-stage')}", f"{SECTION}/{score_row('end-to-end')}"]
    table = load_rows(path=Path(__file__).resolve().parent.parent / "benchmarks" / "results.json")
    assert keys[0] in table and table[keys[0]]["n"] >= 200
    got = side_by_side({keys[2]: row(SECTION, "z", 0.5, [0.45, 0.55], 200)}, PIXEL_ROUTES)
    assert got == {task: [(heads[2][0], 0.5, 0.45, 0.55, 200)]}
