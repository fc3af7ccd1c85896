"""PushT in LeRobot's conventions: corner order, coordinates, block angle and rewards, against references.

References: pymunk itself (gym-pusht builds the T's two boxes with pymunk and lists each box's
corners as pymunk returns them), our PushT env (its keypoint observation and its rewards on the
same states), and one real frame of LeRobot's ``lerobot/pusht_keypoints`` (episode 0, frame 0).
"""

from __future__ import annotations

import numpy as np
import pytest

from coursekit.data import lerobot_pusht as lp
from coursekit.data.features import pusht_keypoint_features
from coursekit.envs import pusht_geometry as geo
from coursekit.envs.pusht import PushTEnv

# lerobot/pusht_keypoints, episode 0, frame 0 (the data set viewer on huggingface.co): observation.state
# and observation.environment_state as stored (float32).
LEROBOT_FRAME_AGENT = np.array([222.0, 97.0])
LEROBOT_FRAME_CORNERS = np.array([
    282.4591979980469, 373.6072692871094, 163.5284423828125, 389.5907897949219, 159.5325469970703, 359.8581237792969,
    278.46331787109375, 343.87457275390625, 233.86427307128906, 349.868408203125, 204.131591796875, 353.8642883300781,
    192.14393615722656, 264.66619873046875, 221.87661743164062, 260.6703186035156])


def gym_pusht_corners(state: np.ndarray) -> np.ndarray:
    """(16,) corners as gym-pusht computes them: pymunk boxes with its vertex lists, each vertex rotated + moved."""
    pymunk = pytest.importorskip("pymunk")
    body = pymunk.Body(1.0, 1.0)
    crossbar = pymunk.Poly(body, [(-60, 30), (60, 30), (60, 0), (-60, 0)])  # gym-pusht's add_tee vertex lists
    stem = pymunk.Poly(body, [(-15, 30), (-15, 120), (15, 120), (15, 30)])
    corners = [v.rotated(state[4]) + pymunk.Vec2d(state[2], state[3]) for shape in (crossbar, stem)
               for v in shape.get_vertices()]
    return np.array([tuple(c) for c in corners]).reshape(-1)


def rollout(seed: int, steps: int = 40):
    """States before each action (T, 5), the actions (T, 2), the env's rewards (T,) and keypoint observations (T, 18)."""
    env = PushTEnv(obs_type="keypoints")
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    states, actions, rewards, keypoints = [], [], [], []
    for _ in range(steps):
        state = env.get_state()[:5]
        action = state[2:4] + rng.normal(0.0, 60.0, size=2)  # aim near the block: contacts turn it
        states.append(state), keypoints.append(obs)
        obs, reward, terminated, truncated, _ = env.step(action)
        actions.append(action), rewards.append(reward)
        if terminated or truncated:
            break
    return np.array(states), np.array(actions), np.array(rewards), np.array(keypoints)


def test_corner_order_is_pymunks():
    assert lp.FROM_COURSEKIT.tolist() == [3, 2, 1, 0, 4, 5, 6, 7]
    rng = np.random.default_rng(0)
    for state in np.c_[rng.uniform(0, 512, (20, 4)), rng.uniform(-20, 20, 20)]:
        np.testing.assert_allclose(lp.lerobot_keypoints(state[None])[0], gym_pusht_corners(state), atol=1e-9)


@pytest.mark.parametrize("seed", [0, 3])
def test_export_corners_are_our_envs_keypoints_reordered(seed):
    states, _, _, keypoints = rollout(seed)
    ours = keypoints[:, 2:].reshape(len(states), 8, 2)[:, lp.FROM_COURSEKIT].reshape(len(states), 16)
    np.testing.assert_allclose(lp.lerobot_keypoints(states), ours, atol=1e-6)
    np.testing.assert_allclose(keypoints[:, :2], states[:, :2])  # observation.state = the agent, same coordinates


def test_a_real_lerobot_frame_is_a_t_at_one_pose():
    pose, error = lp.pose_from_keypoints(LEROBOT_FRAME_CORNERS[None])
    assert error[0] < 1e-3  # float32 corners of a rigid T: micro-pixels
    state = np.concatenate([LEROBOT_FRAME_AGENT, pose[0]])
    np.testing.assert_allclose(lp.lerobot_keypoints(state[None])[0], LEROBOT_FRAME_CORNERS, atol=1e-3)
    np.testing.assert_allclose(gym_pusht_corners(state), LEROBOT_FRAME_CORNERS, atol=1e-3)
    # coursekit's pusht_keypoints features at that state, in LeRobot's order, are the stored frame
    ours = pusht_keypoint_features(state)
    np.testing.assert_allclose(ours[:2], LEROBOT_FRAME_AGENT)
    np.testing.assert_allclose(ours[2:].reshape(8, 2)[lp.FROM_COURSEKIT].reshape(-1), LEROBOT_FRAME_CORNERS, atol=1e-3)


def test_pose_fit_inverts_the_corners():
    rng = np.random.default_rng(1)
    states = np.c_[rng.uniform(0, 512, (200, 4)), rng.uniform(-20, 20, 200)]
    poses, error = lp.pose_from_keypoints(lp.lerobot_keypoints(states))
    assert error.max() < 1e-9
    np.testing.assert_allclose(poses[:, :2], states[:, 2:4], atol=1e-9)
    np.testing.assert_allclose(np.angle(np.exp(1j * (poses[:, 2] - states[:, 4]))), 0.0, atol=1e-12)
    assert np.all((-np.pi < poses[:, 2]) & (poses[:, 2] <= np.pi))


def test_states_from_lerobot_unwraps_within_episodes():
    angles = np.linspace(0.0, 9.0, 30)  # more than a turn: stored corners cannot tell, the unwrap restores it
    states = np.c_[np.full(30, 100.0), np.full(30, 50.0), np.full(30, 256.0), np.full(30, 300.0), angles]
    back = lp.states_from_lerobot(states[:, :2], lp.lerobot_keypoints(states), np.array([30]))
    np.testing.assert_allclose(back, states, atol=1e-9)


def test_corners_in_another_order_are_refused():
    corners = lp.lerobot_keypoints(np.array([[1.0, 2.0, 256.0, 256.0, 0.3]]))
    ours = corners.reshape(8, 2)[np.argsort(lp.FROM_COURSEKIT)].reshape(1, 16)  # coursekit's order, not LeRobot's
    with pytest.raises(ValueError, match=r"frame 0 is not the T's 8 corners in gym-pusht's order"):
        lp.states_from_lerobot(np.zeros((1, 2)), ours, np.array([1]))


@pytest.mark.parametrize("seed", [0, 5])
def test_next_rewards_are_the_envs_rewards_after_each_action(seed):
    states, _, rewards, _ = rollout(seed)
    reward, success = lp.next_rewards(states, np.array([len(states)]))
    np.testing.assert_allclose(reward[:-1], rewards[:-1], atol=1e-6)  # row t: the reward action t earned
    last = geo.reward_from_coverage(geo.coverage(tuple(states[-1, 2:5])))
    assert reward[-1] == pytest.approx(last, abs=1e-6)  # the last next state is not recorded: its own repeats
    np.testing.assert_array_equal(success, reward >= 1.0 - 1e-9)
