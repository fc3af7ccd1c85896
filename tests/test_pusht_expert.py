"""The scripted PushT expert: its geometry and push model against trusted references (shapely,
the closed form, the simulator), and its episodes against the demonstration requirements
(success, smooth targets, no bumps while travelling, rest at the end, determinism, two sides)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from coursekit.envs import pusht_geometry as geo
from coursekit.experts import pusht_clearance as clearance
from coursekit.experts.pusht_config import ExpertConfig
from coursekit.experts.pusht_push_model import candidate_contacts, keypoints, pose_error, predict_pushes
from coursekit.experts.pusht_routes import ANTICLOCKWISE, CLOCKWISE, RoutePlanner, speed_profile_targets

T_LOCAL = shapely.Polygon(geo.T_OUTLINE_LOCAL)


# --------------------------------------------------------------------------------------------
# Geometry and the push model
# --------------------------------------------------------------------------------------------
def test_clearance_matches_shapely():
    rng = np.random.default_rng(0)
    a = rng.uniform(-120, 180, size=(200, 2))
    b = rng.uniform(-120, 180, size=(200, 2))
    want_points = [T_LOCAL.distance(shapely.Point(p)) for p in a]
    want_segments = [T_LOCAL.distance(shapely.LineString([p, q])) for p, q in zip(a, b)]
    np.testing.assert_allclose(clearance.point_distance(a), want_points, atol=1e-9)
    np.testing.assert_allclose(clearance.segment_distance(a, b), want_segments, atol=1e-9)


def test_keypoints_and_pose_error_agree_with_geometry():
    pose = (201.0, 333.0, -7.3)
    np.testing.assert_array_equal(keypoints(np.array(pose)), geo.block_keypoints(pose))
    assert pose_error(np.array(geo.GOAL_POSE)) == pytest.approx(0.0, abs=1e-9)
    assert pose_error(np.array(geo.GOAL_POSE) + [0, 0, 2 * math.pi]) == pytest.approx(0.0, abs=1e-9)
    assert pose_error(np.array(geo.GOAL_POSE) + [3.0, 4.0, 0.0]) == pytest.approx(5.0)


def test_contacts_lie_on_the_boundary_and_the_pusher_fits():
    c = candidate_contacts()
    boundary = T_LOCAL.exterior
    assert max(boundary.distance(shapely.Point(p)) for p in c.point) < 1e-9
    # Pushing inward: a point just along the normal is in the T (or on its edge, at a corner).
    assert all(T_LOCAL.covers(shapely.Point(p + 0.5 * n)) for p, n in zip(c.point, c.normal))
    touching = c.point - c.normal * geo.AGENT_RADIUS
    assert clearance.point_distance(touching).min() >= geo.AGENT_RADIUS - 1e-6
    cog = np.asarray(geo.T_COG_LOCAL)
    lever = (c.point - cog)[:, 0] * c.normal[:, 1] - (c.point - cog)[:, 1] * c.normal[:, 0]
    np.testing.assert_allclose(c.lever, lever)


def test_push_model_small_push_matches_closed_form():
    """First order: the CoG moves J = d / (1 + m k^2 / I) along the normal, the T turns J k / I."""
    c = candidate_contacts()
    pose = np.array([250.0, 240.0, 0.4])
    d = 1e-4
    new = predict_pushes(pose, c, np.array([d]))[:, 0]  # (M, 3)
    j = d / (1.0 + geo.T_MASS * c.lever**2 / geo.T_MOMENT)
    np.testing.assert_allclose(new[:, 2] - pose[2], j * c.lever / geo.T_MOMENT, rtol=1e-6, atol=1e-15)
    cog0 = geo.cog_world(pose)
    cog1 = np.array([geo.cog_world(p) for p in new])
    normal_world = geo.local_to_world(c.normal, (0.0, 0.0, pose[2]))
    np.testing.assert_allclose(cog1 - cog0, j[:, None] * normal_world, rtol=1e-4, atol=1e-12)


def test_push_model_agrees_with_the_simulator():
    """A near-centred push on the stem's end: the model's pose matches the simulator's."""
    from coursekit.envs.pusht import PushTEnv

    c = candidate_contacts()
    i = int(np.argmin(np.abs(c.point - [0.0, 120.0]).sum(1) + np.abs(c.normal - [0.0, -1.0]).sum(1)))
    assert abs(c.lever[i]) <= 5.0
    pose = np.array([256.0, 200.0, 0.0])
    start = c.point[i] - c.normal[i] * (geo.AGENT_RADIUS + 2.0) + pose[:2]  # 2 px short of contact
    env = PushTEnv()
    env.reset(seed=0)
    env.set_state(np.concatenate([start, pose]))
    depth = 30.0
    for k in range(1, 9):
        env.step(start + c.normal[i] * (2.0 + depth) * min(k / 4, 1.0))
    got = env.get_state()[2:5]
    want = predict_pushes(pose, c, np.array([depth]))[i, 0]
    np.testing.assert_allclose(got, want, atol=1.0)
    assert abs(got[1] - pose[1]) > 0.8 * depth  # it really moved


# --------------------------------------------------------------------------------------------
# Routes and speed profiles
# --------------------------------------------------------------------------------------------
def _sweep(points: np.ndarray, centre: np.ndarray) -> float:
    u, v = points[:-1] - centre, points[1:] - centre
    return float(np.arctan2(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0], (u * v).sum(1)).sum())


def test_routes_keep_clear_and_wind_the_right_way():
    planner = RoutePlanner(clearance=21.0, waypoint_clearance=24.0)
    pose = (256.0, 256.0, 0.7)
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(60):
        start, goal = rng.uniform(-150, 200, size=(2, 2))
        if min(clearance.point_distance(start), clearance.point_distance(goal)) < 22:
            continue
        lengths = planner.lengths(pose, start, goal[None])[:, 0]
        for side, length in zip((CLOCKWISE, ANTICLOCKWISE), lengths[1:]):
            if not np.isfinite(length):
                continue
            route = planner.route(pose, start, goal, side)
            local = geo.world_to_local(route.points, pose)
            assert clearance.segment_distance(local[:-1], local[1:]).min() >= 21.0 - 0.5
            assert route.length == pytest.approx(length)
            sweep = _sweep(local, np.asarray(geo.T_COG_LOCAL))
            assert (sweep > 0) == (side == CLOCKWISE)  # clockwise on screen = positive in y-down
            checked += 1
    assert checked > 40


def test_speed_profile_is_bounded_and_ends_on_the_goal():
    pts = np.array([[10.0, 10.0], [210.0, 10.0], [210.0, 150.0], [100.0, 150.0]])
    t = speed_profile_targets(pts, max_speed=35.0, accel=12.0, turn_speed=15.0)
    steps = np.linalg.norm(np.diff(np.concatenate([pts[:1], t]), axis=0), axis=1)
    assert steps.max() <= 35.0 + 1e-9
    np.testing.assert_allclose(t[-1], pts[-1])
    assert steps[0] <= 12.0 + 1e-9  # starts gently
    assert steps[-1] < 5.0  # and brakes before the end


def test_config_validation_names_the_bad_value():
    with pytest.raises(ValueError, match="-3"):
        ExpertConfig(travel_speed=-3.0)
    with pytest.raises(ValueError, match="standoff_gap"):
        ExpertConfig(standoff_gap=20.0, approach_gap=9.0)


# --------------------------------------------------------------------------------------------
# Whole episodes
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def expert():
    from coursekit.experts.pusht_planner import PushTExpert

    return PushTExpert()


@pytest.fixture(scope="module")
def env():
    from coursekit.envs.pusht import PushTEnv

    return PushTEnv(obs_type="state")


def _check_episode(rec, cfg: ExpertConfig) -> None:
    from coursekit.experts.pusht_planner import REST, TRAVEL

    assert rec.success_step is not None and rec.success_step <= 300
    assert rec.finish_step >= rec.success_step
    assert len(rec.states) == rec.finish_step + cfg.rest_steps
    # Smooth 10 Hz targets: no target far from the previous one, nor from the pusher at the start.
    jumps = np.linalg.norm(np.diff(rec.actions, axis=0), axis=1)
    assert jumps.max() <= cfg.travel_speed + 1e-6
    assert np.linalg.norm(rec.actions[0] - rec.states[0, :2]) <= cfg.travel_speed + 1e-6
    # No stray bumps: the block does not move while the pusher travels (beyond the sub-pixel
    # creep of a block settling out of a wall).
    travel = np.flatnonzero(rec.phases[:-1] == TRAVEL)
    moved = np.abs(rec.states[travel + 1, 2:5] - rec.states[travel, 2:5])
    assert moved.max(initial=0.0) < 0.05
    assert rec.travel_bumps == 0
    # Rest at the end: targets on the pusher's own position, the pusher coming to a stop, the
    # coverage staying above 0.95 throughout and above final_coverage at the end.
    rest = rec.phases == REST
    assert rest.sum() == cfg.rest_steps and rest[-cfg.rest_steps:].all()
    np.testing.assert_allclose(rec.actions[rest], rec.states[rest, :2])
    assert np.linalg.norm(rec.states[-1, :2] - rec.states[-2, :2]) < 0.5
    assert (rec.coverage[rest] > geo.SUCCESS_THRESHOLD).all()
    assert rec.coverage[-1] > cfg.final_coverage - 0.005  # the rest check ran on a copied state


@pytest.mark.parametrize("seed", [0, 7, 50, 65, 158])  # 50: pusher starts inside the T; 65: T in a
# wall; 158: the pusher ends a push touching a corner and must step out before travelling
def test_expert_solves_reference_resets_like_a_person(expert, env, seed):
    rec = expert.run_episode(env, seed)
    _check_episode(rec, expert.config)


def test_expert_is_deterministic(expert, env):
    a = expert.run_episode(env, 3)
    b = expert.run_episode(env, 3)
    for name in ("states", "actions", "coverage", "phases"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    assert a.route_choices == b.route_choices


@pytest.fixture(scope="module")
def two_way_runs(expert):
    from coursekit.experts.pusht_planner import TWO_WAY_START
    from coursekit.viz.expert_plots import expert_runs_from

    return expert_runs_from(TWO_WAY_START, range(8), expert=expert)


def test_coin_picks_both_sides_from_one_start(two_way_runs):
    for rec in two_way_runs:
        assert rec.success_step is not None
        assert rec.route_choices and rec.route_choices[0]["step"] == 0  # a choice right away
    assert {rec.route_choices[0]["taken"] for rec in two_way_runs} == {CLOCKWISE, ANTICLOCKWISE}
    # Same start, different ways: the pusher paths really differ.
    first = two_way_runs[0]
    other = next(r for r in two_way_runs if r.route_choices[0]["taken"] != first.route_choices[0]["taken"])
    n = min(len(first.states), len(other.states), 25)
    assert np.abs(first.states[:n, :2] - other.states[:n, :2]).max() > 100.0


def test_two_ways_figure(two_way_runs):
    from matplotlib.figure import Figure

    from coursekit.viz.expert_plots import SIDE_COLORS, plot_choice_summary, plot_two_ways

    fig = plot_two_ways(records=two_way_runs)
    assert isinstance(fig, Figure) and len(fig.axes) == 2
    colours = {line.get_color() for line in fig.axes[0].lines}
    assert {SIDE_COLORS["cw"], SIDE_COLORS["ccw"]} <= colours
    summary = plot_choice_summary([r.route_choices for r in two_way_runs] + [[]])
    heights = [p.get_height() for p in summary.axes[0].patches]
    assert sum(heights) == 9 and heights[0] == 1


def test_dart_noise_executes_noisy_targets_and_records_the_expert(expert, env):
    """DART (Laskey et al. 2017): the env runs target + N(0, sigma^2) per axis, the record keeps
    the clean target. Replaying the recorded targets plus the same seeded noise stream in a fresh
    env must reproduce every recorded state exactly; without the noise it must not."""
    from coursekit.envs.pusht import PushTEnv
    from coursekit.experts.pusht_planner import NOISE_STREAM

    seed, sigma = 11, 10.0
    rec = expert.run_episode(env, seed, action_noise=sigma)
    assert rec.success_step is not None
    clean = expert.run_episode(env, seed)
    assert len(rec.states) != len(clean.states) or not np.array_equal(rec.states, clean.states)
    for with_noise in (True, False):
        replay = PushTEnv(obs_type="state", max_episode_steps=1000)
        replay.reset(seed=seed)
        rng = np.random.default_rng([NOISE_STREAM, seed])
        states = []
        for action in rec.actions:
            states.append(replay.get_state()[:5].copy())
            executed = np.clip(action + rng.normal(0.0, sigma, size=2), 0.0, geo.WORLD_SIZE) if with_noise else action
            replay.step(executed)
        if with_noise:
            np.testing.assert_array_equal(np.stack(states), rec.states)
        else:
            assert np.abs(np.stack(states) - rec.states).max() > 1.0
    # The recorded targets are the planner's: smooth, even though the pusher was shaken.
    assert np.linalg.norm(np.diff(rec.actions, axis=0), axis=1).max() <= expert.config.travel_speed + 1e-6
    again = expert.run_episode(env, seed, action_noise=sigma)
    assert np.array_equal(again.states, rec.states) and np.array_equal(again.actions, rec.actions)


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf")])
def test_dart_noise_rejects_bad_levels(expert, env, bad):
    with pytest.raises(ValueError, match="action_noise"):
        expert.run_episode(env, 0, action_noise=bad)
