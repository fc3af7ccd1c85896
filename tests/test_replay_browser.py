"""The evaluation replay in a real headless browser: the page draws the scene (not a blank canvas)
and plays the episodes one after another (two moments of the time line show different pictures).

Screenshots are taken after ``budget_ms`` of the page's virtual time; the page spends about 0.7 s
of it loading, so a budget of 300 ms shows the first step and 5000 ms shows about 4.3 s in.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
pytest.importorskip("meshcat")
from PIL import Image  # noqa: E402

from headless_chromium import screenshot_html  # noqa: E402
from coursekit.viz.replay import EpisodeRecording, write_replay  # noqa: E402

pytestmark = pytest.mark.browser



def shot(html, png, budget_ms: int) -> np.ndarray:
    """(600, 800, 3) float RGB screenshot after ``budget_ms`` virtual milliseconds."""
    return np.asarray(Image.open(screenshot_html(html, png, budget_ms=budget_ms)).convert("RGB"), dtype=np.float64)


def assert_not_blank(img: np.ndarray) -> None:
    assert img.shape == (600, 800, 3)
    scene = img[120:]  # below the caption box
    # meshcat's background is a vertical gradient: compare each row with its own left-edge colour
    background = np.median(scene[:, :4], axis=1, keepdims=True)  # (H, 1, 3)
    drawn = (np.abs(scene - background).max(axis=-1) > 30).mean()
    assert drawn > 0.1, f"only {drawn:.1%} of the picture differs from the background"
    assert len(np.unique((scene // 16).reshape(-1, 3), axis=0)) > 20, "too few colours for a rendered scene"


def block_centroid_x(img: np.ndarray) -> float:
    from coursekit.envs.pusht_render import BLOCK_COLOR

    ys, xs = np.nonzero(np.linalg.norm(img[120:] - np.array(BLOCK_COLOR), axis=-1) < 25)
    assert len(xs) > 500, "block not visible"
    return float(xs.mean())


def still_block(seed: int, block_x: float, steps: int) -> EpisodeRecording:
    """(steps + 1, 5) states of a PushT episode whose pusher sweeps the bottom while the T stays at block_x."""
    agent_x = np.linspace(100.0, 400.0, steps + 1)
    states = np.column_stack([agent_x, np.full(steps + 1, 450.0), np.full(steps + 1, block_x),
                              np.full(steps + 1, 250.0), np.zeros(steps + 1)])
    return EpisodeRecording(seed, states, 0.1, False, f"T at x = {block_x:.0f}")


def test_pusht_replay_plays_the_episodes_in_turn(chromium, tmp_path):
    # episode 1: 15 steps (1.5 s + 1 s hold) with the T on the left; episode 2: 80 steps with it on the right
    html = write_replay(tmp_path / "rec", "pusht", [still_block(1, 150.0, 15), still_block(2, 360.0, 80)])["html"]
    first = shot(html, tmp_path / "first.png", 300)
    later = shot(html, tmp_path / "later.png", 5000)
    for img in (first, later):
        assert_not_blank(img)
    x_first, x_later = block_centroid_x(first), block_centroid_x(later)
    assert x_later > x_first + 100, f"block centroid at x = {x_first:.0f} px early vs {x_later:.0f} px in episode 2"


def test_arm_pair_replay_is_drawn_and_moves(chromium, tmp_path):
    from coursekit.envs.aloha import AlohaTransferCubeEnv
    from coursekit.experts.aloha_scripted import scripted_episode

    env = AlohaTransferCubeEnv()
    episode, _ = scripted_episode("transfer_cube", seed=0, env=env)
    env.close()
    recording = EpisodeRecording(0, episode["physics_qpos"], float(episode["stage"].max()), True, "scripted")
    html = write_replay(tmp_path / "rec", "transfer_cube", [recording])["html"]
    first = shot(html, tmp_path / "first.png", 300)
    later = shot(html, tmp_path / "later.png", 5000)
    for img in (first, later):
        assert_not_blank(img)
        dark = (img[120:].max(axis=-1) < 90).mean()  # the arms are dark grey links
        assert 0.005 < dark < 0.3, f"dark (arm) pixels cover {dark:.2%}"
    moved = (np.abs(later[120:] - first[120:]).max(axis=-1) > 40).mean()
    assert moved > 0.005, f"only {moved:.2%} of the pixels changed between 0.3 s and 5 s: the arms did not move"
