"""Replays a person can look at: episodes from the real PushT expert and the real scripted arm pair
go in; a self-contained meshcat page whose animation follows the recorded states, and a grid whose
panels are exactly the envs' own renderings, come out. Bad input is refused before any file is written."""

from __future__ import annotations

import base64
import re

import numpy as np
import pytest
from PIL import Image

pytest.importorskip("meshcat")
pytest.importorskip("mujoco")
import umsgpack  # noqa: E402  (meshcat's own message format)

from coursekit.tasks import INSERTION, PUSHT, TRANSFER_CUBE  # noqa: E402
from coursekit.viz.replay import (  # noqa: E402
    CAPTION_H, GAP, HEADER_H, MARGIN, EpisodeRecording, panel_origin, timeline, write_replay,
)


@pytest.fixture(scope="module")
def scene():
    from coursekit.viz.meshcat.scene import MeshcatScene

    with MeshcatScene() as s:
        yield s


@pytest.fixture(scope="module")
def pusht_episodes() -> list[EpisodeRecording]:
    """Two real expert episodes, cut after 12 and 20 steps (a success and a failure, by their score)."""
    from coursekit.envs.pusht import PushTEnv
    from coursekit.experts.pusht_planner import PushTExpert

    out = []
    for seed, steps in ((3, 12), (4, 20)):
        env = PushTEnv()
        ep = PushTExpert().run_episode(env, seed=seed)
        states = ep.states[:steps + 1]  # (T + 1, 5): the state before each action, and after the last
        out.append(EpisodeRecording(seed, states, float(ep.coverage[:steps + 1].max()), seed == 3, f"expert {steps}"))
    return out


@pytest.fixture(scope="module")
def cube_episode() -> EpisodeRecording:
    """A real scripted transfer-cube demonstration, every 4th step of its first 200."""
    from coursekit.envs.aloha import AlohaTransferCubeEnv
    from coursekit.experts.aloha_scripted import scripted_episode

    env = AlohaTransferCubeEnv()
    episode, _ = scripted_episode("transfer_cube", seed=0, env=env)
    env.close()
    return EpisodeRecording(0, episode["physics_qpos"][:200:4], float(episode["stage"].max()), True)


def commands(page: str) -> list[dict]:
    """meshcat's commands embedded in an exported page (base64 msgpack blobs)."""
    blobs = re.findall(r"data:application/octet-binary;base64,([A-Za-z0-9+/=]+)", page)
    return [umsgpack.unpackb(base64.b64decode(b)) for b in blobs]


def animation_tracks(page: str) -> dict[str, dict[str, list]]:
    """{meshcat path: {track name: keyframes}} of the page's one animation."""
    (anim,) = [c for c in commands(page) if c["type"] == "set_animation"]
    assert anim["options"]["play"] is True
    return {a["path"]: {t["name"]: t["keys"] for t in a["clip"]["tracks"]} for a in anim["animations"]}


def assert_self_contained(page: str) -> None:
    assert not re.search(r"<script[^>]*\ssrc\s*=", page), "a script is loaded from elsewhere"
    assert not re.search(r"<link[^>]*https?://", page), "a stylesheet is loaded from elsewhere"
    assert "MeshCat.Viewer" in page and len(page) > 500_000  # three.js and the viewer are inlined


def test_pusht_replay_follows_the_recorded_states(tmp_path, scene, pusht_episodes):
    from coursekit.envs.pusht_render import PushTRenderer
    from coursekit.viz.meshcat.pusht import PushTMeshcat

    out = write_replay(tmp_path / "rec", "pusht", pusht_episodes, scene=scene)
    assert out == {"html": tmp_path / "rec" / "replay.html", "frames": tmp_path / "rec" / "frames.png"}
    page = out["html"].read_text()
    assert_self_contained(page)
    for ep in pusht_episodes:  # the caption box names every episode
        assert f"seed {ep.seed} | score {ep.score:.3g} | {'success' if ep.success else 'failure'}" in page

    # one after another at 10 Hz, each final state held for a second
    starts, hold = timeline([len(ep.states) for ep in pusht_episodes], fps=10.0)
    assert hold == 10 and list(starts) == [0, 13 + 10]
    block = animation_tracks(page)["/meshcat/pusht/block"][".position"]
    assert len(block) == sum(len(ep.states) + hold for ep in pusht_episodes)
    for ep, start in zip(pusht_episodes, starts):
        for frame, state in ((start, ep.states[0]), (start + len(ep.states) - 1 + hold, ep.states[-1])):
            want = PushTMeshcat.transforms(state)["block"][:3, 3]
            assert block[frame]["time"] == frame
            np.testing.assert_allclose(block[frame]["value"], want, atol=1e-12)

    # frames.png: one row per episode; each panel is exactly the env renderer's picture
    grid = np.asarray(Image.open(out["frames"]).convert("RGB"))
    h, w = PUSHT.replay.panel_hw
    assert grid.shape == (2 * MARGIN + HEADER_H + 2 * (CAPTION_H + h + GAP) - GAP, 2 * MARGIN + 2 * w + GAP, 3)
    renderer = PushTRenderer((h, w))
    for r, ep in enumerate(pusht_episodes):
        for c, state in enumerate((ep.states[0], ep.states[-1])):
            y, x = panel_origin(r, c, "pusht")
            np.testing.assert_array_equal(grid[y:y + h, x:x + w], renderer.render(state))
        caption = grid[y - CAPTION_H:y, MARGIN:MARGIN + w].astype(int)  # text in green (success) or red
        green = ((caption[..., 1] > caption[..., 0] + 40) & (caption[..., 1] > caption[..., 2] + 40)).sum()
        red = ((caption[..., 0] > caption[..., 1] + 60) & (caption[..., 0] > caption[..., 2] + 60)).sum()
        assert (green > 30 and red == 0) if ep.success else (red > 30 and green == 0)


def test_pusht_replay_takes_what_a_rollout_records(tmp_path, scene, pusht_episodes):
    """The rollout's default recorder gives PushTEnv.get_state(): (T + 1, 7); the velocity is ignored."""
    ep = pusht_episodes[0]
    seven = np.column_stack([ep.states, np.ones((len(ep.states), 2))])
    a = write_replay(tmp_path / "five", "pusht", [ep], scene=scene)
    b = write_replay(tmp_path / "seven", "pusht", [EpisodeRecording(ep.seed, seven, ep.score, ep.success, ep.label)],
                     scene=scene)
    assert a["frames"].read_bytes() == b["frames"].read_bytes()
    assert animation_tracks(a["html"].read_text()) == animation_tracks(b["html"].read_text())


def test_arm_pair_replay(tmp_path, scene, cube_episode):
    from coursekit.envs.aloha import AlohaTransferCubeEnv

    out = write_replay(tmp_path, "transfer_cube", [cube_episode], scene=scene)
    page = out["html"].read_text()
    assert_self_contained(page)
    tracks = animation_tracks(page)
    env = AlohaTransferCubeEnv()
    cube = env.model.geom("cube").id
    (cube_path,) = [p for p in tracks if re.search(rf"/geoms/{cube:03d}_cube$", p)]
    keys = tracks[cube_path][".position"]
    assert len(keys) == len(cube_episode.states) + 50  # 50 Hz, one second held at the end
    # the cube's keyframes are its world position by MuJoCo's forward kinematics of the recorded qpos
    xpos = []
    for q in cube_episode.states[[0, -1]]:
        env.set_physics_state(q)
        xpos.append(env.data.geom_xpos[cube].copy())
    np.testing.assert_allclose(keys[0]["value"], xpos[0], atol=1e-9)
    np.testing.assert_allclose(keys[-1]["value"], xpos[1], atol=1e-9)
    assert xpos[1][2] > xpos[0][2] + 0.05, "the demonstration should have lifted the cube"

    grid = np.asarray(Image.open(out["frames"]).convert("RGB"))
    h, w = TRANSFER_CUBE.replay.panel_hw
    assert grid.shape == (2 * MARGIN + HEADER_H + CAPTION_H + h, 2 * MARGIN + 2 * w + GAP, 3)
    for c, q in enumerate(cube_episode.states[[0, -1]]):
        env.set_physics_state(q)
        want = env.render_camera(TRANSFER_CUBE.replay.camera, (h, w)).astype(int)
        y, x = panel_origin(0, c, "transfer_cube")
        assert np.abs(grid[y:y + h, x:x + w].astype(int) - want).max() <= 1
    env.close()


def test_insertion_replay_from_a_live_env(tmp_path, scene):
    """States read the way an evaluation reads them: env.get_physics_state()["physics_qpos"] per step."""
    from coursekit.envs.aloha import AlohaInsertionEnv
    from coursekit.envs.aloha.model import start_qpos14

    env = AlohaInsertionEnv()
    env.reset(seed=7)
    states = [env.get_physics_state()["physics_qpos"]]
    for _ in range(5):
        env.step(start_qpos14())
        states.append(env.get_physics_state()["physics_qpos"])
    env.close()
    out = write_replay(tmp_path, "insertion", [EpisodeRecording(7, np.array(states), 0.0, False, "idle")], fps=25,
                       scene=scene)
    (anim,) = [c for c in commands(out["html"].read_text()) if c["type"] == "set_animation"]
    assert {a["clip"]["fps"] for a in anim["animations"]} == {25}
    assert Image.open(out["frames"]).size[1] == 2 * MARGIN + HEADER_H + CAPTION_H + INSERTION.replay.panel_hw[0]


def test_bad_input_is_refused_naming_the_value(tmp_path, scene, pusht_episodes, cube_episode):
    ep = pusht_episodes[0]
    with pytest.raises(ValueError, match="unknown task 'push_t'"):
        write_replay(tmp_path, "push_t", [ep])
    with pytest.raises(ValueError, match=r"seed 0\): transfer_cube states must be MuJoCo qpos of shape \(T \+ 1, 23\)"):
        write_replay(tmp_path, "transfer_cube", [EpisodeRecording(0, ep.states, 1.0, True)])
    recorded = np.column_stack([np.zeros((len(cube_episode.states), 16)), cube_episode.states])
    with pytest.raises(ValueError, match=r"recorded evaluation row of transfer_cube: pass states\[:, 16:\]"):
        write_replay(tmp_path, "transfer_cube", [EpisodeRecording(0, recorded, 1.0, True)])
    with pytest.raises(ValueError, match=r"seed 0\): PushT states must have shape"):
        write_replay(tmp_path, "pusht", [cube_episode])
    with pytest.raises(ValueError, match="1 to 24 episodes, got 0"):
        write_replay(tmp_path, "pusht", [])
    with pytest.raises(ValueError, match="wrap it in a list"):
        write_replay(tmp_path, "pusht", ep)
    with pytest.raises(ValueError, match="fps must be a positive finite number, got -1"):
        write_replay(tmp_path, "pusht", [ep], fps=-1)
    with pytest.raises(ValueError, match=r"states must be finite, got nan at step 2, column 1"):
        bad = ep.states.copy()
        bad[2, 1] = np.nan
        EpisodeRecording(5, bad, 0.5, False)
    with pytest.raises(ValueError, match="score must be a finite number, got inf"):
        EpisodeRecording(5, ep.states, float("inf"), False)
    with pytest.raises(ValueError, match="seed must be an int, got '5'"):
        EpisodeRecording("5", ep.states, 0.5, False)
    assert list(tmp_path.iterdir()) == []  # nothing was written


def test_never_overwrites_a_file_it_did_not_create(tmp_path, scene, pusht_episodes):
    (tmp_path / "replay.html").write_text("mine")
    with pytest.raises(FileExistsError, match="replay.html"):
        write_replay(tmp_path, "pusht", pusht_episodes[:1], scene=scene)
    assert (tmp_path / "replay.html").read_text() == "mine"
    assert not (tmp_path / "frames.png").exists()
    out = write_replay(tmp_path, "pusht", pusht_episodes[:1], overwrite=True, scene=scene)
    assert out["html"].read_text() != "mine"
    (tmp_path / "file").write_text("x")
    with pytest.raises(NotADirectoryError, match="file"):
        write_replay(tmp_path / "file", "pusht", pusht_episodes[:1], scene=scene)


def test_every_task_with_a_replay_drawing_is_drawn_by_a_viewer():
    from coursekit.envs.aloha.tasks import TASKS as ARM_TASKS
    from coursekit.tasks import TASKS
    from coursekit.viz.replay_viewers import VIEWERS

    assert all(t.replay.viewer in VIEWERS for t in TASKS.values() if t.replay is not None)
    assert sorted(ARM_TASKS) == sorted(t.name for t in TASKS.values() if t.replay and t.replay.viewer == "mujoco")
