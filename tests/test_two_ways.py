"""Where PushT is multimodal (two-way starts, which way a path goes) and how a policy moves (stalls, jerk)."""

import json
import math

import numpy as np
import pytest

from coursekit.envs import pusht_geometry as geo
from coursekit.evaluate.behaviour import rms_jerk, stalled_steps, still_steps
from coursekit.envs.pusht_geometry import local_to_world
from coursekit.experts.pusht_two_ways import first_decision, path_side, path_sweep


def _arc(pose, radius, start, stop, n=9):
    """World points on a circle round the T's centre of gravity; body-frame angle start -> stop (rad)."""
    t = np.linspace(start, stop, n)
    local = np.asarray(geo.T_COG_LOCAL) + radius * np.stack([np.cos(t), np.sin(t)], axis=1)
    return local_to_world(local, pose)


@pytest.mark.parametrize("pose", [(256.0, 256.0, 0.0), (200.0, 300.0, 1.3), (300.0, 180.0, -2.5)])
def test_path_side_by_geometric_construction(pose):
    # y points down on screen, so a growing angle (x = r cos t, y = r sin t) turns clockwise.
    cw = _arc(pose, 150.0, 0.0, math.pi / 2)
    assert path_sweep(cw, pose) == pytest.approx(math.pi / 2)
    assert path_side(cw, pose) == "cw"
    assert path_side(cw[::-1], pose) == "ccw"
    centre = local_to_world(np.asarray(geo.T_COG_LOCAL), pose)
    towards = centre + np.linspace(200.0, 80.0, 5)[:, None] * np.array([[0.6, 0.8]])  # straight at the T
    assert path_side(towards, pose) == "none"
    assert path_side(np.repeat(cw[:1], 5, axis=0), pose) == "none"  # standing still
    assert path_side(_arc(pose, 150.0, 0.0, math.radians(10)), pose) == "none"  # less than 20 degrees


def test_path_side_rejects_bad_input():
    with pytest.raises(ValueError, match="K >= 2"):
        path_sweep(np.zeros((1, 2)), (0, 0, 0))
    with pytest.raises(ValueError, match="min_sweep"):
        path_side(np.zeros((3, 2)) + 1, (0, 0, 0), min_sweep=0.0)


@pytest.mark.parametrize("seed", [100001, 100004])
def test_first_decision_matches_the_planners_own_coin_toss(seed):
    """On a two-way start the classifier must name the side the planner's coin chose."""
    from coursekit.envs.pusht import PushTEnv
    from coursekit.experts.pusht_planner import PushTExpert

    decision = first_decision(seed)
    rec = PushTExpert().run_episode(PushTEnv(obs_type="state"), seed)
    assert decision.two_way and rec.route_choices
    assert decision.side == rec.route_choices[0]["taken"]


def test_first_decision_one_way_start_and_the_cached_table():
    d = first_decision(100000)
    assert not d.two_way and d.success
    from benchmarks.bench_claims import TABLE

    cached = json.loads(TABLE.read_text())["seeds"]
    for seed in (100000, 100001, 100002):
        fresh = first_decision(seed)
        assert cached[str(seed)]["two_way"] == fresh.two_way and cached[str(seed)]["side"] == fresh.side, seed
    with pytest.raises(ValueError, match="seed"):
        first_decision(-1)


def _states_against_stem(n_steps):
    """Pusher resting just below the stem's bottom edge of a T at (256, 256, 0): (1, n+1, 5)."""
    block = np.array([256.0, 256.0, 0.0])
    pusher = local_to_world(np.array([0.0, 120.0 + geo.AGENT_RADIUS + 1.0]), block)
    row = np.concatenate([pusher, block])
    return np.repeat(row[None, None], n_steps + 1, axis=1)


def test_stalled_steps_counts_only_still_contact():
    s = _states_against_stem(10)
    assert stalled_steps(s, np.array([10])).tolist() == [10]
    assert stalled_steps(s, np.array([4])).tolist() == [4]  # padding after the episode ends is ignored
    moving = s.copy()
    moving[0, :, 0] += np.arange(11) * 3.0  # the pusher slides along the edge at 3 px/step
    assert stalled_steps(moving, np.array([10])).tolist() == [0]
    pushing = s.copy()
    pushing[0, :, 3] -= np.arange(11) * 1.0  # the T moves 1 px/step: a push, not a stall
    assert stalled_steps(pushing, np.array([10])).tolist() == [0]
    far = s.copy()
    far[0, :, 1] += 40.0  # still, but 40 px away from the T
    assert stalled_steps(far, np.array([10])).tolist() == [0]
    with pytest.raises(ValueError, match="length"):
        stalled_steps(s, np.array([11]))


def test_rms_jerk_is_the_third_difference():
    t = np.arange(20.0)
    quadratic = np.stack([3 + 2 * t - 0.5 * t**2, t], axis=-1)[None]  # (1, T, 2): zero third difference
    assert rms_jerk(quadratic)[0] == pytest.approx(0.0, abs=1e-9)
    cubic = np.stack([0.1 * t**3, np.zeros_like(t)], axis=-1)[None]  # third difference 0.6 on dim 0, 0 on dim 1
    assert rms_jerk(cubic)[0] == pytest.approx(math.sqrt(0.6**2 / 2))
    assert rms_jerk(cubic, dims=[0])[0] == pytest.approx(0.6)
    noisy = np.concatenate([cubic, cubic + np.random.default_rng(0).normal(0, 1, cubic.shape)])
    assert rms_jerk(noisy, length=np.array([20, 20]))[1] > 1.0
    with pytest.raises(ValueError, match="length"):
        rms_jerk(cubic, length=np.array([3]))


def test_still_steps_counts_slow_pusher_steps_in_a_window():
    s = _states_against_stem(10)
    s[0, 6:, 0] += np.arange(1, 6) * 5.0  # still for 5 steps, then moves 5 px/step
    assert still_steps(s, np.array([10])).tolist() == [5]
    assert still_steps(s, np.array([10]), first=3).tolist() == [3]
    assert still_steps(s, np.array([2])).tolist() == [2]


def test_two_route_reference_paths_and_nearest():
    """bench_two_route's classifier: the mean cw / ccw first chunks and their average (MSE's optimum
    on an even mixture); each chunk is named after the nearest of the three."""
    from types import SimpleNamespace

    from benchmarks.bench_two_route import nearest_path, reference_paths

    up = np.stack([np.linspace(0, 100, 5), np.linspace(0, -50, 5)], axis=1)  # (5, 2): round one side
    down = up * np.array([1.0, -1.0])  # the mirror image: round the other side
    runs = [SimpleNamespace(actions=a, route_choices=[{"taken": s}]) for a, s in ((up, "cw"), (down, "ccw"))] * 2
    refs = reference_paths(runs, horizon=5)
    assert np.allclose(refs["cw"], up) and np.allclose(refs["ccw"], down)
    assert np.allclose(refs["between"], (up + down) / 2)  # the straight line between them
    chunks = np.stack([up + 3.0, down - 3.0, (up + down) / 2 + 1.0])  # (3, 5, 2)
    assert nearest_path(chunks, refs) == ["cw", "ccw", "between"]


def test_two_route_starts_move_only_the_pusher_within_the_jitter_and_are_seeded():
    from benchmarks.bench_two_route import jittered_starts
    from coursekit.experts.pusht_planner import TWO_WAY_START

    starts = jittered_starts(500, 5.0)  # (500, 5)
    assert starts.shape == (500, 5)
    offset = np.linalg.norm(starts[:, :2] - np.asarray(TWO_WAY_START[:2]), axis=1)  # (500,)
    assert offset.max() <= 5.0 and offset.min() < 0.5 and np.median(offset) > 3.0  # uniform over the disc's area
    np.testing.assert_array_equal(starts[:, 2:], np.tile(TWO_WAY_START[2:], (500, 1)))  # the block as at the tie
    np.testing.assert_array_equal(starts, jittered_starts(500, 5.0))
    np.testing.assert_array_equal(jittered_starts(3, 0.0), np.tile(TWO_WAY_START, (3, 1)))
