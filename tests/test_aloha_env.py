"""The ALOHA arm pair: model facts against the published kinematics, gymnasium API, bad input,
determinism, rendering and physics-state round trips."""

from __future__ import annotations

import importlib.util

import gymnasium
import numpy as np
import pytest

if importlib.util.find_spec("mujoco") is None:
    pytest.skip("mujoco is not installed", allow_module_level=True)

# coursekit.envs.aloha first: it sets MUJOCO_GL=egl, which must happen before mujoco loads.
from coursekit.envs.aloha import AlohaInsertionEnv, AlohaTransferCubeEnv  # noqa: E402

import coursekit  # noqa: E402,F401  (registers the gymnasium ids)
import mujoco  # noqa: E402
from coursekit.envs.aloha.model import (  # noqa: E402
    ARM_JOINTS,
    START_ARM_QPOS,
    ArmPairIndex,
    gripper_normalize,
    gripper_unnormalize,
    load_model,
    start_qpos14,
)

PUBLISHED_RANGES = {  # ACT / ViperX 300 s joint limits (rad; m for the fingers)
    "waist": (-3.14158, 3.14158), "shoulder": (-1.85005, 1.25664), "elbow": (-1.76278, 1.6057),
    "forearm_roll": (-3.14158, 3.14158), "wrist_angle": (-1.8675, 2.23402), "wrist_rotate": (-3.14158, 3.14158),
    "left_finger": (0.021, 0.057), "right_finger": (-0.057, -0.021),
}
PUBLISHED_KP = {"waist": 800, "shoulder": 1600, "elbow": 800, "forearm_roll": 10, "wrist_angle": 50, "wrist_rotate": 20,
                "left_finger": 200, "right_finger": 200}
PUBLISHED_FORCE = {"waist": 150, "shoulder": 300, "elbow": 100, "forearm_roll": 100}


@pytest.fixture(scope="module")
def cube_model() -> mujoco.MjModel:
    return load_model("transfer_cube")


def _rot_y(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def test_joint_limits_gains_and_timing_match_published(cube_model):
    m = cube_model
    assert m.opt.timestep == pytest.approx(0.002)
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    for arm in ("left", "right"):
        for joint, (lo, hi) in PUBLISHED_RANGES.items():
            np.testing.assert_allclose(m.joint(f"{arm}/{joint}").range, [lo, hi], atol=1e-6)
            act = m.actuator(f"{arm}/{joint}")
            assert act.gainprm[0] == PUBLISHED_KP[joint]
            assert act.biasprm[1] == -PUBLISHED_KP[joint]  # a position servo: force = kp (ctrl - q)
        for joint, limit in PUBLISHED_FORCE.items():
            np.testing.assert_allclose(m.actuator(f"{arm}/{joint}").forcerange, [-limit, limit])


def test_bases_placed_and_right_arm_yawed(cube_model):
    m = cube_model
    np.testing.assert_allclose(m.body("left/base").pos, [-0.469, 0.5, 0.0])
    np.testing.assert_allclose(m.body("right/base").pos, [0.469, 0.5, 0.0])
    # yaw by pi: quaternion (0, 0, 0, 1) up to sign
    np.testing.assert_allclose(np.abs(m.body("right/base").quat), [0, 0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(m.body("left/shoulder_link").pos, [0, 0, 0.079])
    np.testing.assert_allclose(m.body("left/upper_forearm_link").pos, [0.05955, 0, 0.3])


def test_forward_kinematics_matches_closed_form_planar_chain(cube_model):
    """At the start pose the arm moves in its vertical plane: gripper_link position in closed form."""
    m, d = cube_model, mujoco.MjData(cube_model)
    idx = ArmPairIndex.from_model(m)
    idx.set_arm_pose(d, np.concatenate([START_ARM_QPOS, START_ARM_QPOS]), 0.03)
    mujoco.mj_kinematics(m, d)
    _, th_s, th_e, _, th_w, _ = START_ARM_QPOS
    p = np.array([0, 0, 0.079 + 0.04805])
    p = p + _rot_y(th_s) @ [0.05955, 0, 0.3]
    p = p + _rot_y(th_s + th_e) @ [0.2 + 0.1, 0, 0]
    p = p + _rot_y(th_s + th_e + th_w) @ [0.069744, 0, 0]
    np.testing.assert_allclose(d.body("left/gripper_link").xpos, p + [-0.469, 0.5, 0], atol=1e-9)
    mirrored = (p * [-1, 1, 1]) + [0.469, 0.5, 0]  # the right arm is the left one turned by pi
    np.testing.assert_allclose(d.body("right/gripper_link").xpos, mirrored, atol=1e-9)


def test_only_palms_pads_table_and_objects_collide(cube_model):
    m = cube_model
    colliding = {m.geom(i).name for i in range(m.ngeom) if m.geom_contype[i] or m.geom_conaffinity[i]}
    expected = {"table", "cube"} | {f"{a}/{g}" for a in ("left", "right") for g in ("palm", "left_pad", "right_pad")}
    assert colliding == expected
    pad = m.geom("left/left_pad")
    np.testing.assert_allclose(pad.size * 2, [0.04, 0.008, 0.024])
    np.testing.assert_allclose(pad.friction, [1.5, 0.05, 0.0001])
    assert pad.condim == 4


def test_gripper_normalisation_round_trip_and_action_to_fingers(cube_model):
    x = np.linspace(0.01, 0.058, 7)
    np.testing.assert_allclose(gripper_unnormalize(gripper_normalize(x)), x)
    assert gripper_normalize(0.01844) == pytest.approx(0.0) and gripper_normalize(0.058) == pytest.approx(1.0)
    d = mujoco.MjData(cube_model)
    idx = ArmPairIndex.from_model(cube_model)
    action = start_qpos14()
    action[6], action[13] = 0.5, 1.0
    idx.set_action(d, action)
    np.testing.assert_allclose(d.ctrl[idx.finger_act[0]], [gripper_unnormalize(0.5), -gripper_unnormalize(0.5)])
    np.testing.assert_allclose(d.ctrl[idx.arm_act], np.concatenate([START_ARM_QPOS, START_ARM_QPOS]))
    assert len(ARM_JOINTS) == 6


@pytest.mark.parametrize("env_id", ["coursekit/AlohaTransferCube-v0", "coursekit/AlohaInsertion-v0"])
def test_gymnasium_env_checker(env_id):
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make(env_id).unwrapped
    check_env(env, skip_render_check=True)
    env.close()


@pytest.mark.parametrize("cls", [AlohaTransferCubeEnv, AlohaInsertionEnv])
def test_same_seed_same_episode_and_spawn_in_published_ranges(cls):
    env_a, env_b = cls(), cls()
    obs_a, _ = env_a.reset(seed=7)
    obs_b, _ = env_b.reset(seed=7)
    rng = np.random.default_rng(0)
    for _ in range(15):
        action = obs_a["qpos"] + rng.normal(0, 0.05, 14)
        obs_a, ra, *_ = env_a.step(action)
        obs_b, rb, *_ = env_b.step(action)
    for key in obs_a:
        np.testing.assert_array_equal(obs_a[key], obs_b[key])
    for seed in range(30):
        state = env_a.reset(seed=seed)[0]["env_state"]
        for (x_range, y_range, z), pose in zip(env_a.task.spawn_ranges, state.reshape(-1, 7)):
            assert x_range[0] <= pose[0] <= x_range[1] and y_range[0] <= pose[1] <= y_range[1]
            assert pose[2] == pytest.approx(z)
    assert not np.allclose(env_a.reset(seed=1)[0]["env_state"], env_a.reset(seed=2)[0]["env_state"])


def test_bad_actions_raise_or_clip():
    env = AlohaTransferCubeEnv()
    obs, _ = env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(13))
    bad = obs["qpos"].copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        env.step(bad)
    far = obs["qpos"].copy()
    far[1] = 5.0  # shoulder beyond its +1.26 rad limit
    far[6] = 3.0  # gripper beyond fully open
    env.step(far)
    assert env.data.ctrl[env.model.actuator("left/shoulder").id] == pytest.approx(1.25664)
    assert env.data.ctrl[env.model.actuator("left/left_finger").id] == pytest.approx(0.058)


def test_unstable_simulation_ends_episode_with_flag(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo appends its warning to MUJOCO_LOG.TXT in the working directory
    env = AlohaTransferCubeEnv()
    obs, _ = env.reset(seed=0)
    state = env.get_physics_state()
    env.set_physics_state(state["physics_qpos"], np.full(env.model.nv, 1e200))
    obs, _, terminated, truncated, info = env.step(obs["qpos"])
    assert terminated and not truncated and info["sim_unstable"]
    assert all(np.all(np.isfinite(v)) for v in obs.values())


def test_episode_truncates_at_max_steps():
    env = AlohaTransferCubeEnv(max_episode_steps=3)
    obs, _ = env.reset(seed=0)
    flags = [env.step(obs["qpos"])[3] for _ in range(3)]
    assert flags == [False, False, True]


def test_pixels_and_rerender_from_stored_physics_state():
    env = AlohaTransferCubeEnv(obs_type="pixels", render_size=(48, 64), render_mode="rgb_array")
    obs, _ = env.reset(seed=3)
    assert obs["pixels"].shape == (48, 64, 3) and obs["pixels"].dtype == np.uint8
    assert obs["pixels"].std() > 5  # an actual image, not a blank buffer
    obs, *_ = env.step(obs["qpos"] + 0.1)
    live = env.render()
    stored = env.get_physics_state()["physics_qpos"]
    other = AlohaTransferCubeEnv()
    other.reset(seed=99)
    other.set_physics_state(stored)
    np.testing.assert_array_equal(other.render_camera("top", size=(48, 64)), live)
    assert other.render_camera("angle", size=32).shape == (32, 32, 3)
    with pytest.raises(ValueError, match="camera"):
        other.render_camera("nope")
    with pytest.raises(ValueError, match="qpos"):
        other.set_physics_state(stored[:-1])
    env.close()
    other.close()


def test_rendering_does_not_change_the_dynamics():
    state_env, pixel_env = AlohaTransferCubeEnv(), AlohaTransferCubeEnv(obs_type="pixels", render_size=16)
    obs_s, _ = state_env.reset(seed=4)
    obs_p, _ = pixel_env.reset(seed=4)
    for k in range(10):
        action = obs_s["qpos"] + 0.02 * k
        obs_s, *_ = state_env.step(action)
        obs_p, *_ = pixel_env.step(action)
    np.testing.assert_array_equal(obs_s["qpos"], obs_p["qpos"])
    pixel_env.close()


def _place(env, env_state):
    """Put the objects at ``env_state`` (arms at their start pose) and update contacts/kinematics."""
    env.reset(seed=0)
    env.task.set_env_state(env.data, np.asarray(env_state, dtype=float))
    mujoco.mj_forward(env.model, env.data)


def test_strict_insertion_check_is_geometric():
    env = AlohaInsertionEnv()
    socket = np.array([-0.1, 0.5, 0.2, 1, 0, 0, 0])
    yaw_pi = [0, 0, 0, 1]
    cases = {  # peg pose relative to the socket -> inserted?
        "tip at the pin": ([0.08, 0, 0], [1, 0, 0, 0], True),
        "turned round, tip at the pin": ([0.08, 0, 0], yaw_pi, True),
        "tip at the mouth only": ([0.12, 0, 0], [1, 0, 0, 0], False),
        "beside the socket": ([0.08, 0.05, 0], [1, 0, 0, 0], False),
        "far away": ([0.3, 0, 0], [1, 0, 0, 0], False),
    }
    for name, (offset, quat, expected) in cases.items():
        peg = np.concatenate([socket[:3] + offset, quat])
        _place(env, np.concatenate([peg, socket]))
        assert env.strict_success() is expected, name
    _place(env, env.task.spawn(np.random.default_rng(0)))
    assert env.stage() == 0 and not env.strict_success()


def test_strict_cube_check_needs_the_left_grip():
    env = AlohaTransferCubeEnv()
    _place(env, [0.1, 0.5, 0.02, 1, 0, 0, 0])  # resting on the table
    assert not env.strict_success() and env.stage() == 0
    _place(env, [0.1, 0.5, 0.2, 1, 0, 0, 0])  # in mid-air but held by nobody
    assert not env.strict_success()
