"""Scripted ALOHA demonstrations: the replayed episodes succeed strictly, datasets round-trip,
and the waypoint tools behave (interpolation, quaternions)."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

if importlib.util.find_spec("mujoco") is None:
    pytest.skip("mujoco is not installed", allow_module_level=True)

from coursekit.envs.aloha import AlohaInsertionEnv, AlohaTransferCubeEnv  # noqa: E402  (sets MUJOCO_GL first)

from coursekit.data import ActionChunks, EpisodeDataset  # noqa: E402
from coursekit.experts.aloha_scripted import (  # noqa: E402
    EPISODE_STEPS,
    ScriptConfig,
    collect,
    collect_transfer_cube,
    scripted_episode,
    worker_context,
)
from coursekit.experts.aloha_waypoints import Waypoint, interpolate, quat_axis_angle, quat_mul, quat_slerp  # noqa: E402


def test_quaternion_helpers_against_rotation_matrices():
    import mujoco

    q = quat_mul(quat_axis_angle((0, 0, 1), 180), quat_axis_angle((0, 1, 0), 60))
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, q)
    # yaw pi then pitch 60 deg: the gripper's x axis points to -x and down
    np.testing.assert_allclose(mat.reshape(3, 3)[:, 0], [-0.5, 0, -np.sqrt(3) / 2], atol=1e-12)
    half = quat_slerp(np.array([1.0, 0, 0, 0]), quat_axis_angle((1, 0, 0), 90), 0.5)
    np.testing.assert_allclose(half, quat_axis_angle((1, 0, 0), 45), atol=1e-12)


def test_interpolate_is_linear_between_waypoints_and_clamped():
    q = (1.0, 0.0, 0.0, 0.0)
    wps = [Waypoint(0, (0, 0, 0), q, 0.0), Waypoint(10, (1, 2, 3), q, 1.0)]
    xyz, quat, g = interpolate(wps, 5)
    np.testing.assert_allclose(xyz, [0.5, 1, 1.5])
    assert g == pytest.approx(0.5)
    np.testing.assert_allclose(interpolate(wps, 50)[0], [1, 2, 3])
    with pytest.raises(ValueError, match="increasing"):
        interpolate(wps[::-1], 3)


def test_script_config_validates():
    with pytest.raises(ValueError, match="95"):
        ScriptConfig(pick_pitch_deg=95)
    with pytest.raises(ValueError, match="220"):
        ScriptConfig(release_start=220)


@pytest.mark.parametrize("task, env_cls, seed", [("transfer_cube", AlohaTransferCubeEnv, 11), ("insertion", AlohaInsertionEnv, 11)])
def test_scripted_episode_succeeds_strictly_after_replay(task, env_cls, seed):
    env = env_cls()
    episode, ee = scripted_episode(task, seed, env=env)
    assert bool(ee["strict_success"]), "the end-effector rollout itself failed"
    assert bool(episode["strict_success"]) and bool(episode["lenient_success"])
    assert episode["action"].shape == (EPISODE_STEPS, 14) and episode["qpos"].shape == (EPISODE_STEPS, 14)
    assert episode["stage"].max() == 4
    # the replayed joints track the end-effector rollout closely (the replay IS that trajectory)
    assert np.abs(episode["qpos"][1:, :6] - ee["qpos"][1:EPISODE_STEPS, :6]).max() < 0.1
    if task == "transfer_cube":  # the final state: cube held high by the left gripper
        assert episode["env_state"][-1, 2] > 0.15


def test_collect_round_trip_deterministic_and_chunkable(tmp_path):
    data = collect_transfer_cube(2, seed=5, progress=False)  # default: up to 2 worker processes
    assert data.n_episodes == 2 and data.meta["env_id"] == "coursekit/AlohaTransferCube-v0"
    assert data.meta["strict_successes"] >= 2 and data.meta["episode_seeds"][0] == 5
    for key, dim in (("qpos", 14), ("qvel", 14), ("action", 14), ("env_state", 7)):
        assert data[key].shape == (2 * EPISODE_STEPS, dim)
    path = data.save(tmp_path / "cube.npz")
    loaded = EpisodeDataset.load(path)
    for key in data.arrays:
        np.testing.assert_array_equal(loaded[key], data[key])
    assert loaded.meta["episode_seeds"] == data.meta["episode_seeds"]
    # replaying the stored actions from the stored start reproduces the stored observations
    ep = loaded.episode(1)
    env = AlohaTransferCubeEnv()
    obs, _ = env.reset(options={"env_state": ep["env_state"][0]})
    for t in range(50):
        np.testing.assert_allclose(obs["qpos"], ep["qpos"][t], atol=1e-12)
        obs, *_ = env.step(ep["action"][t])
    # images can be rendered after the fact from the stored physics state
    env.set_physics_state(ep["physics_qpos"][200], ep["physics_qvel"][200])
    assert env.render_camera("top", size=(24, 32)).shape == (24, 32, 3)
    chunks = ActionChunks.build(loaded.episode_ends, chunk_size=100)
    obs_b, act_b, pad_b = chunks.gather(loaded["qpos"], loaded["action"], np.array([0, len(chunks) - 1]))
    assert act_b.shape == (2, 100, 14) and pad_b[1, 1:].all() and not pad_b[0].any()
    # same seed, same data, whether collected by worker processes or in this one
    again = collect("transfer_cube", 1, seed=5, progress=False, workers=1)
    np.testing.assert_array_equal(again["action"], data.episode(0)["action"])


def test_collect_workers_never_fork_the_caller(tmp_path):
    """The caller may be a Jupyter kernel, whose ZMQ threads make fork unsafe (issue 22): workers
    start from a forkserver, so they import the caller's main module, and an unguarded script that
    asks for workers gets one clear line (a forked worker would have run it without a word)."""
    assert worker_context().get_start_method() in ("forkserver", "spawn")
    script = tmp_path / "unguarded.py"
    script.write_text("from coursekit.experts.aloha_scripted import collect\n"
                      "collect('transfer_cube', 1, seed=5, progress=False, workers=2)\n")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)}
    proc = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode != 0, proc.stdout
    assert 'its top level must be guarded by `if __name__ == "__main__":`; or pass workers=1' in proc.stderr, proc.stderr[-2000:]


def test_the_advice_workers_1_works_through_the_task_api(tmp_path):
    """The error above says "or pass workers=1": an unguarded script that follows it through
    ``get_task(...).collect`` (what a practitioner calls) runs in-process and gets the same data."""
    script = tmp_path / "unguarded_one_worker.py"
    script.write_text("import numpy as np\n"
                      "from coursekit.tasks import get_task\n"
                      "from coursekit.experts.aloha_scripted import collect\n"
                      "a = get_task('transfer_cube').collect(1, 5, progress=False, workers=1)\n"
                      "b = collect('transfer_cube', 1, seed=5, progress=False, workers=1)\n"
                      "np.testing.assert_array_equal(a['action'], b['action'])\n"
                      "print('same', a.meta['episode_seeds'])\n")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)}
    proc = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "same [5]" in proc.stdout, proc.stdout
