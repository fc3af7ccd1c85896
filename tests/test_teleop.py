"""Teleoperation: the recorder (driven without a browser), exact replay, mixing, the widget's protocol.

The trusted reference is the scripted expert: fed the expert's own targets from the same reset,
the recorder must reproduce the expert's recorded states bit for bit, and write the same arrays
(names, dtypes, trailing shapes) as ``coursekit collect pusht``.
"""

from __future__ import annotations

import numpy as np
import pytest

from coursekit.data.episodes import DatasetError, EpisodeDataset
from coursekit.envs.pusht import PushTEnv
from coursekit.experts.pusht_planner import TWO_WAY_START, collect_dataset
from coursekit.teleop import (PUSH, REST, TRAVEL, TeleopConfig, TeleopRecorder, mix, path_targets, replay,
                              route_side)
from coursekit.viz.expert_plots import expert_runs_from


@pytest.fixture(scope="module")
def coin_runs():
    return expert_runs_from(TWO_WAY_START, coin_seeds=range(4))


@pytest.fixture(scope="module")
def expert_data():
    return collect_dataset(2, seed=0, progress=False)


def test_recorder_reproduces_the_expert_and_writes_its_fields(coin_runs, expert_data, tmp_path):
    rec = TeleopRecorder(reset_state=TWO_WAY_START, config=TeleopConfig(rest_steps=5))
    for run in coin_runs:
        rec.record(run.actions)
    data = EpisodeDataset.load(rec.save(tmp_path / "mine.npz"))
    assert data.n_episodes == len(coin_runs)
    for i, run in enumerate(coin_runs):
        ep = data.episode(i)
        n = len(ep["action"])
        # the expert rests rest_steps after finishing, so both stop within a step or two of each other
        assert abs(n - len(run.actions)) <= 5
        np.testing.assert_array_equal(ep["state"], run.states[:n])
        np.testing.assert_array_equal(ep["action"], run.actions[:n])
        np.testing.assert_allclose(ep["coverage"], run.coverage[:n], rtol=0, atol=1e-12)
        assert data.meta["success_steps"][i] == run.success_step
    assert sorted(data.arrays) == sorted(expert_data.arrays)
    for key in data.arrays:
        assert data[key].dtype == expert_data[key].dtype, key
        assert data[key].shape[1:] == expert_data[key].shape[1:], key
    for key in ("env_id", "obs_type", "state_columns", "action_columns", "phase_names"):
        assert data.meta[key] == expert_data.meta[key], key
    assert data.meta["routes"] == [run.route_choices[0]["taken"] for run in coin_runs]


def test_replay_in_a_fresh_env_is_exact_even_with_other_envs_alive(tmp_path):
    rec = TeleopRecorder(first_seed=7)
    wobble = path_targets([[100, 100], [300, 120], [260, 330], [90, 400]], speed=18.0, hold=3)
    rec.record(wobble)
    rec.record(wobble[::-1])
    data = EpisodeDataset.load(rec.save(tmp_path / "mine.npz"))
    assert data.meta["episode_resets"] == [{"seed": 7}, {"seed": 8}] and data.meta["episode_seeds"] == [7, 8]
    crowd = [PushTEnv() for _ in range(5)]  # other worlds in the same process must not matter
    for env, s in zip(crowd, range(5)):
        env.reset(seed=s)
        env.step([256.0, 256.0])
    for i in range(data.n_episodes):
        np.testing.assert_array_equal(replay(data, i), data.episode(i)["state"])


def test_episode_ends_by_itself_after_success_and_rest_or_at_max_steps(coin_runs):
    rec = TeleopRecorder(reset_state=TWO_WAY_START, config=TeleopConfig(rest_steps=3))
    run = coin_runs[0]
    index = rec.record(np.vstack([run.actions, np.repeat(run.actions[-1:], 50, axis=0)]))
    ep = rec.episodes[index]
    success = rec.success_steps[index]
    assert success == run.success_step and len(ep["action"]) == success + 3
    assert set(ep["phase"][success:]) == {REST} and REST not in set(ep["phase"][:success])
    assert {TRAVEL, PUSH} <= set(ep["phase"][:success].tolist())
    short = TeleopRecorder(config=TeleopConfig(max_steps=6))
    short.start()
    steps = [short.step([20.0, 20.0]) for _ in range(6)]
    assert steps == [True] * 5 + [False] and len(short.episodes[0]["action"]) == 6


def test_stop_discard_and_bad_input():
    rec = TeleopRecorder()
    with pytest.raises(RuntimeError, match="start"):
        rec.step([1.0, 2.0])
    rec.start()
    assert rec.stop() is None and rec.episodes == []  # nothing recorded: nothing kept
    rec.start()
    rec.step([200.0, 200.0])
    rec.discard()
    assert rec.episodes == [] and not rec.recording
    rec.start()
    with pytest.raises(ValueError, match="shape"):
        rec.step([1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="finite"):
        rec.step([np.nan, 2.0])
    with pytest.raises(ValueError, match="max_steps must be an int >= 1, got 0"):
        TeleopConfig(max_steps=0)
    with pytest.raises(ValueError, match="first_seed"):
        TeleopRecorder(first_seed=-1)
    with pytest.raises(DatasetError, match="no episode kept"):
        TeleopRecorder().dataset()


def test_a_path_is_extended_never_clobbered(tmp_path, expert_data):
    path = tmp_path / "mine.npz"
    first = TeleopRecorder(path=path, first_seed=3)
    first.record(path_targets([[50, 50], [120, 80]], hold=2))
    assert EpisodeDataset.load(path).n_episodes == 1  # written at stop()
    again = TeleopRecorder(path=path)  # a new session continues the file and the seeds
    assert len(again.episodes) == 1 and again.next_reset() == {"seed": 4}
    again.record(path_targets([[60, 60], [90, 90]]))
    data = EpisodeDataset.load(path)
    assert data.n_episodes == 2 and data.meta["episode_seeds"] == [3, 4]
    other = expert_data.save(tmp_path / "expert.npz")
    before = other.read_bytes()
    with pytest.raises(DatasetError, match="not a teleoperation recording"):
        TeleopRecorder(path=other)
    assert other.read_bytes() == before


def test_route_side_matches_the_experts_coin(coin_runs):
    for run in coin_runs:
        assert route_side(run.states, run.phases) == run.route_choices[0]["taken"]
    still = np.tile(np.array([[100.0, 100.0, 300.0, 300.0, 0.0]]), (10, 1))
    assert route_side(still) is None


def test_mixed_data_trains(expert_data, tmp_path, capsys):
    from coursekit.cli import main

    rec = TeleopRecorder(first_seed=500)
    rec.record(path_targets([[80, 80], [250, 300], [300, 300]], hold=4))
    mixed = mix(expert_data, rec.dataset())
    assert mixed.n_episodes == expert_data.n_episodes + 1
    assert mixed.meta["episode_seeds"] == sorted([*expert_data.meta["episode_seeds"], 500])
    assert mixed.meta["sources"] == [[expert_data.meta["expert"], 2], ["coursekit.teleop", 1]]
    np.testing.assert_array_equal(mixed["state"][: expert_data.n_steps], expert_data["state"])
    path = mixed.save(tmp_path / "mixed.npz")
    out = tmp_path / "ckpt"
    assert main(["train", "--data", str(path), "--steps", "2", "--out", str(out), "--threads", "1",
                 "--no-progress", "--down-dims", "16,32"]) == 0
    assert (out / "config.json").is_file()
    with pytest.raises(ValueError, match="at least one"):
        mix()


def test_widget_protocol_without_a_browser(tmp_path):
    """The messages the page sends (start, tick, stop, discard) drive the recorder; traits follow."""
    from coursekit.viz.teleop_widget import TeleopWidget

    path = tmp_path / "w.npz"
    w = TeleopWidget(path=path, first_seed=11)
    start = w.agent
    w._on_message(w, {"event": "start"}, [])
    assert w.recording and w.n_steps == 0
    for i in range(4):
        w._on_message(w, {"event": "tick", "target": [start[0] + 10 * i, start[1]]}, [])
    assert w.n_steps == 4 and w.agent != start
    w._on_message(w, {"event": "tick", "target": ["a", 1]}, [])
    assert "bad target" in w.status and w.n_steps == 4
    w._on_message(w, {"event": "stop"}, [])
    assert not w.recording and w.n_kept == 1
    data = EpisodeDataset.load(path)
    assert data.n_episodes == 1 and len(data["action"]) == 4 and data.meta["episode_resets"] == [{"seed": 11}]
    np.testing.assert_array_equal(replay(data, 0), data["state"])
    w._on_message(w, {"event": "start"}, [])
    w._on_message(w, {"event": "tick", "target": [10, 10]}, [])
    w._on_message(w, {"event": "discard"}, [])
    assert w.n_kept == 1 and "discarded" in w.status
    with pytest.raises(ValueError, match="size"):
        TeleopWidget(size=20)
