"""Real-browser checks: exported meshcat pages really draw the scene in headless chromium.

Each test exports a rollout's HTML, screenshots it with headless chromium (SwiftShader WebGL,
flags in ``tests/headless_chromium.py``) and checks the picture: the objects' colours cover plausible areas and
the image is not blank. The colours are the scene's own (``pusht_render`` constants, the MuJoCo
model's rgba); Lambert shading keeps lit top faces close to them.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

pytest.importorskip("meshcat")
from PIL import Image  # noqa: E402

from headless_chromium import screenshot_html  # noqa: E402

pytestmark = pytest.mark.browser



@pytest.fixture(scope="module")
def scene():
    from coursekit.viz.meshcat.scene import MeshcatScene

    with MeshcatScene() as s:
        yield s


def load_rgb(path) -> np.ndarray:
    """(H, W, 3) float RGB of a screenshot."""
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.float64)


def colour_mask(img: np.ndarray, rgb, tol: float) -> np.ndarray:
    """(H, W) pixels within Euclidean distance ``tol`` of colour ``rgb`` (0-255)."""
    return np.linalg.norm(img - np.asarray(rgb, dtype=np.float64), axis=-1) < tol


def assert_not_blank(img: np.ndarray) -> None:
    assert img.shape == (600, 800, 3)
    assert img.std() > 10, "the screenshot is (nearly) uniform: nothing was drawn"
    assert len(np.unique((img // 16).reshape(-1, 3), axis=0)) > 20, "too few colours for a rendered scene"


def pusht_states(n: int, start_x: float, end_x: float) -> np.ndarray:
    """(n, 5) states: the block slides along x at y = 300 with the pusher behind it."""
    bx = np.linspace(start_x, end_x, n)
    return np.column_stack([bx - 80, np.full(n, 330.0), bx, np.full(n, 300.0), np.full(n, 0.4)])


def block_centroid_x(img: np.ndarray) -> float:
    from coursekit.envs.pusht_render import BLOCK_COLOR

    ys, xs = np.nonzero(colour_mask(img, BLOCK_COLOR, 25))
    assert len(xs) > 500, "block not visible"
    return float(xs.mean())


def test_pusht_rollout_page_shows_the_scene(chromium, scene, tmp_path):
    from coursekit.envs.pusht import PushTEnv
    from coursekit.envs.pusht_render import AGENT_COLOR, BLOCK_COLOR, GOAL_COLOR
    from coursekit.viz.meshcat.pusht import export_pusht_rollout

    env = PushTEnv()
    env.reset(seed=3)
    states, actions = [], []
    for t in range(30):  # walk the pusher towards the block and into it
        s = env.get_state()
        a = s[:2] + np.clip(s[2:4] - s[:2], -25, 25)
        states.append(s)
        actions.append(a)
        env.step(a)
    html = export_pusht_rollout(np.array(states), tmp_path / "pusht.html", actions=np.array(actions),
                                play=False, scene=scene)
    img = load_rgb(screenshot_html(html, tmp_path / "pusht.png"))
    assert_not_blank(img)
    block = colour_mask(img, BLOCK_COLOR, 25).mean()
    goal = colour_mask(img, GOAL_COLOR, 25).mean()
    agent = colour_mask(img, AGENT_COLOR, 40).mean()
    arena = colour_mask(img, (255, 255, 255), 12).mean()
    # a T (6300 of the arena's 512^2 units, ~2.4 %) seen at an angle: about 1 % of the window
    assert 0.003 < block < 0.05, f"block covers {block:.2%} of the picture"
    assert 0.003 < goal < 0.05, f"goal covers {goal:.2%}"
    assert 0.0003 < agent < 0.02, f"pusher covers {agent:.2%}"
    assert 0.2 < arena < 0.8, f"white arena covers {arena:.2%}: the camera does not frame the scene"


def test_pusht_animation_plays_in_the_browser(chromium, scene, tmp_path):
    """Paused at the first step vs playing for the page's 5 s of virtual time: the block moved right."""
    from coursekit.viz.meshcat.pusht import export_pusht_rollout

    states = pusht_states(120, 120.0, 400.0)  # 12 s at 10 Hz: still sliding when the shot is taken
    still = export_pusht_rollout(states, tmp_path / "still.html", play=False, scene=scene)
    moving = export_pusht_rollout(states, tmp_path / "moving.html", play=True, scene=scene)
    x_still = block_centroid_x(load_rgb(screenshot_html(still, tmp_path / "still.png")))
    x_moving = block_centroid_x(load_rgb(screenshot_html(moving, tmp_path / "moving.png")))
    assert x_moving > x_still + 30, f"block centroid x {x_still:.0f} px paused vs {x_moving:.0f} px playing"


def test_mujoco_page_draws_every_geom_type(chromium, scene, tmp_path):
    import mujoco

    from coursekit.viz.meshcat.mujoco_model import GEOM_GALLERY_XML, MujocoMeshcat

    model = mujoco.MjModel.from_xml_string(GEOM_GALLERY_XML)
    viewer = MujocoMeshcat(model, scene, camera=(50.0, -90.0))
    viewer.animate_qpos(np.array([model.qpos0]), play=False)
    img = load_rgb(screenshot_html(viewer.save_html(tmp_path / "geoms.html"), tmp_path / "geoms.png"))
    assert_not_blank(img)
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    hi, lo = 70.0, 0.45  # a lit saturated primary: its channel(s) bright, the others far below
    masks = {
        "box (red)": (r > hi) & (g < lo * r) & (b < lo * r),
        "sphere (green)": (g > hi) & (r < lo * g) & (b < lo * g),
        "capsule (blue)": (b > hi) & (r < lo * b) & (g < lo * b),
        "cylinder (yellow)": (r > hi) & (g > hi) & (b < lo * np.minimum(r, g)),
        "ellipsoid (magenta)": (r > hi) & (b > hi) & (g < lo * np.minimum(r, b)),
        "mesh (cyan, from its material)": (g > hi) & (b > hi) & (r < lo * np.minimum(g, b)),
    }
    for name, mask in masks.items():
        assert mask.mean() > 0.001, f"{name} covers only {mask.mean():.3%} of the picture"


def test_aloha_rollout_page_shows_the_arm_pair(chromium, scene, tmp_path):
    """A scripted transfer-cube demonstration exported whole; the page opens on its first step."""
    pytest.importorskip("mujoco")
    from coursekit.envs.aloha import AlohaTransferCubeEnv
    from coursekit.experts.aloha_scripted import scripted_episode
    from coursekit.viz.meshcat.mujoco_model import MujocoMeshcat, geom_rgba

    env = AlohaTransferCubeEnv()
    episode, _ = scripted_episode("transfer_cube", seed=0, env=env)
    qpos = episode["physics_qpos"]  # (T, nq): the full MuJoCo state before each action
    viewer = MujocoMeshcat(env.model, scene)
    viewer.animate_qpos(qpos, fps=50, play=False)
    html = viewer.save_html(tmp_path / "aloha.html")
    assert html.stat().st_size < 5_000_000  # 400 steps of 21 moving geoms: about 2 MB
    img = load_rgb(screenshot_html(html, tmp_path / "aloha.png"))
    assert_not_blank(img)
    table = 255 * geom_rgba(env.model, env.model.geom("table").id)[:3]
    cube = 255 * geom_rgba(env.model, env.model.geom("cube").id)[:3]
    env.close()
    assert 0.05 < colour_mask(img, table, 40).mean() < 0.7, "the table top should fill a good part of the view"
    assert colour_mask(img, cube, 60).mean() > 0.0001, "the cube is not visible"
    dark = (img.max(axis=-1) < 90).mean()  # the arms are dark grey links
    assert 0.005 < dark < 0.3, f"dark (arm) pixels cover {dark:.2%}"


def test_notebook_iframe_shows_the_scene(chromium, scene, tmp_path):
    """What a notebook cell shows: the exported page inside show_html's iframe srcdoc."""
    from coursekit.envs.pusht_render import BLOCK_COLOR, GOAL_COLOR
    from coursekit.viz.meshcat.pusht import PushTMeshcat
    from coursekit.viz.notebook import show_html

    viewer = PushTMeshcat(scene)
    viewer.animate(pusht_states(5, 200.0, 220.0), play=False)
    cell = show_html(viewer.html(), height=500).data
    wrapper = tmp_path / "cell.html"
    wrapper.write_text(f"<!DOCTYPE html><html><body style='margin:0'>{cell}</body></html>")
    img = load_rgb(screenshot_html(wrapper, tmp_path / "cell.png"))
    assert_not_blank(img)
    assert colour_mask(img[:500], BLOCK_COLOR, 25).mean() > 0.003, "block not drawn inside the iframe"
    assert colour_mask(img[:500], GOAL_COLOR, 25).mean() > 0.002, "goal not drawn inside the iframe"
    assert colour_mask(img[520:], (255, 255, 255), 3).mean() > 0.9, "below the 500 px iframe the page is blank"
