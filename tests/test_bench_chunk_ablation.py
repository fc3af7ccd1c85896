"""benchmarks/bench_chunk_ablation.py: runs and rows on other demonstrations never mix with the shipped data's."""

from __future__ import annotations

from pathlib import Path

import benchmarks.bench_chunk_ablation as bca


def test_runs_on_another_data_set_get_their_own_folder():
    out, name = Path("/cache"), "Diffusion Policy DDIM-10 (To=2, Tp=16, Ta=8)"
    shipped = bca.run_dir(out, name, 0, 20000, Path("/anywhere") / bca.DATA.name)
    assert shipped == out / "diffusion-policy-ddim-10-to-2-tp-16-ta-8_seed0_s20000"  # the runs in progress keep it
    person = bca.run_dir(out, name, 0, 20000, Path("/d/pusht_400ep_seed0_noise0-5_person.npz"))
    assert person != shipped and person.name.endswith("_person")
    assert bca.run_dir(out, name, 1, 20000, Path("/d") / bca.DATA.name) != shipped  # seed and budget too
    assert bca.run_dir(out, name, 0, 6000, Path("/d") / bca.DATA.name) != shipped


def test_rows_on_person_like_demonstrations_are_named_apart():
    assert bca.data_label({}) == ""
    assert bca.data_label({"expert_style": None}) == ""
    assert bca.data_label({"expert_style": {"choice_tolerance": 0.3}}) == ", person-like demonstrations"


def test_a_row_on_other_demonstrations_names_them_in_its_command(tmp_path, monkeypatch):
    import benchmarks.results

    commands = []
    monkeypatch.setattr(benchmarks.results, "record", lambda section, name, value, unit, cmd, **k: commands.append(cmd))
    monkeypatch.setattr(bca, "part_train", lambda args, seeds, rec: rec("x", (0.5, 0.4, 0.6, 3), "note"))
    person = tmp_path / "pusht_400ep_seed0_noise0-5_person.npz"
    person.write_bytes(b"")
    for data in (person, tmp_path / bca.DATA.name):
        data.touch()
        bca.main(["--only", "train", "--steps", "6000", "--data", str(data), "--out", str(tmp_path / "runs")])
    assert commands[0].endswith(f" --data {person}")  # reproduces the row: the same file
    assert "--data" not in commands[1]  # the planner's demonstrations are the default
