"""PushT geometry against closed forms and an independent shapely construction."""

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import MultiPolygon, Polygon

from coursekit.envs import pusht_geometry as geo


def test_t_area_and_shapes():
    crossbar, stem = geo.block_polygons((0.0, 0.0, 0.0))
    assert crossbar.shape == (4, 2) and stem.shape == (4, 2)
    assert Polygon(crossbar).area + Polygon(stem).area == pytest.approx(geo.T_AREA)
    assert geo.t_shape((10.0, 20.0, 0.3)).area == pytest.approx(6300.0)
    assert geo.block_keypoints(geo.GOAL_POSE).shape == (8, 2)


def test_local_to_world_matches_rotation_matrix():
    pose = (100.0, 50.0, 0.7)
    pt = np.array([[3.0, -4.0]])
    c, s = math.cos(0.7), math.sin(0.7)
    expected = np.array([100 + c * 3 - s * -4, 50 + s * 3 + c * -4])
    np.testing.assert_allclose(geo.local_to_world(pt, pose)[0], expected)


def test_one_body_to_world_transform_vectorised_over_poses():
    """Many poses at once give, bit for bit, what one pose at a time gives; each is R(angle) p + (x, y)
    (checked against the rotation matrix); world_to_local inverts it; every user reads this one transform."""
    from coursekit.data.features import pusht_keypoint_features
    from coursekit.experts.pusht_push_model import keypoints

    rng = np.random.default_rng(0)
    poses = np.column_stack([rng.uniform(0, 512, (50, 2)), rng.uniform(-20, 20, 50)])  # (50, 3)
    pts = rng.uniform(-100, 150, (7, 2))
    batch = geo.local_to_world(pts, poses[:, None, :])  # (50, 7, 2)
    assert batch.shape == (50, 7, 2)
    for pose, world in zip(poses, batch):
        np.testing.assert_array_equal(world, geo.local_to_world(pts, pose))
        c, s = math.cos(pose[2]), math.sin(pose[2])
        np.testing.assert_allclose(world, pts @ np.array([[c, -s], [s, c]]).T + pose[:2], rtol=0, atol=1e-9)
    np.testing.assert_allclose(geo.world_to_local(batch, poses[:, None, :]), np.broadcast_to(pts, batch.shape),
                               rtol=0, atol=1e-9)
    np.testing.assert_array_equal(keypoints(poses), np.stack([geo.block_keypoints(p) for p in poses]))
    states = np.column_stack([rng.uniform(0, 512, (50, 2)), poses])  # (50, 5) [ax, ay, bx, by, angle]
    np.testing.assert_array_equal(pusht_keypoint_features(states)[:, 2:],
                                  np.stack([geo.block_keypoints(p).reshape(-1) for p in poses]).astype(np.float32))
    with pytest.raises(ValueError, match=r"pose must have shape \(\.\.\., 3\)"):
        geo.local_to_world(pts, (1.0, 2.0))
    with pytest.raises(ValueError, match="pose must be finite"):
        geo.local_to_world(pts, (1.0, 2.0, float("nan")))


def test_coverage_at_goal_is_one_and_far_away_zero():
    assert geo.coverage(geo.GOAL_POSE) == pytest.approx(1.0, abs=1e-12)
    assert geo.coverage((256.0 + 300, 256.0, 0.0)) == 0.0


def test_coverage_shift_along_crossbar_closed_form():
    # Shift the block by d along the goal's own x axis: crossbar overlap (120 - d) * 30,
    # stem overlap (30 - d) * 90, no cross terms (the bars' y ranges do not overlap).
    x, y, a = geo.GOAL_POSE
    for d in (4.0, 10.0, 25.0):
        pose = (x + d * math.cos(a), y + d * math.sin(a), a)
        expected = ((120 - d) * 30 + (30 - d) * 90) / 6300
        assert geo.coverage(pose) == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("pose", [(250.0, 260.0, 0.7), (300.0, 200.0, 2.0), (256.0, 256.0, -1.0)])
def test_coverage_matches_independent_multipolygon(pose):
    # The reference builds a MultiPolygon of the two boxes; compare with our single outline.
    def multi(p):
        return MultiPolygon([Polygon(b) for b in geo.block_polygons(p)])

    goal = multi(geo.GOAL_POSE)
    expected = shapely.area(shapely.intersection(goal, multi(pose))) / goal.area
    assert geo.coverage(pose) == pytest.approx(expected, abs=1e-9)


def test_reward_clip():
    assert geo.reward_from_coverage(0.95) == pytest.approx(1.0)
    assert geo.reward_from_coverage(0.475) == pytest.approx(0.5)
    assert geo.reward_from_coverage(1.0) == 1.0


def test_legacy_pose_rotates_about_cog():
    # The CoG's world position must be the same as with angle 0 at the requested position.
    pos, ang = (200.0, 150.0), 1.1
    pose = geo.legacy_pose(pos, ang)
    np.testing.assert_allclose(geo.cog_world(pose), geo.cog_world((pos[0], pos[1], 0.0)))
    assert pose[2] == ang


def test_bad_pose_raises():
    with pytest.raises(ValueError, match="shape"):
        geo.block_polygons((1.0, 2.0))
    with pytest.raises(ValueError, match="finite"):
        geo.coverage((float("nan"), 0.0, 0.0))


@settings(max_examples=60, deadline=None)
@given(x=st.floats(150, 360), y=st.floats(150, 360), a=st.floats(-10, 10))
def test_coverage_properties(x, y, a):
    cov = geo.coverage((x, y, a))
    assert 0.0 <= cov <= 1.0 + 1e-12
    assert geo.coverage((x, y, a + 2 * math.pi)) == pytest.approx(cov, abs=1e-9)  # angle wraps
    # symmetric: area(A & B) / area(T) does not depend on which one is the goal
    assert geo.coverage(geo.GOAL_POSE, goal_pose=(x, y, a)) == pytest.approx(cov, abs=1e-9)
