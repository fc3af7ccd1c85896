"""PushT rasteriser: shapes, reference colours where they must be, no action target in observations."""

import numpy as np
import pytest

from coursekit.envs import pusht_geometry as geo
from coursekit.envs import pusht_render as pr
from coursekit.envs.pusht import PushTEnv

# Block far from the goal, pusher in a free corner.
STATE = np.array([80.0, 430.0, 400.0, 60.0, 0.0])


def _px(img, world_xy):
    h, w = img.shape[:2]
    return img[int(world_xy[1] * h / 512), int(world_xy[0] * w / 512)]


@pytest.mark.parametrize("size", [96, 200, (64, 128)])
def test_colours_at_known_points(size):
    img = pr.render_state(STATE, size)
    hw = (size, size) if isinstance(size, int) else size
    assert img.shape == (*hw, 3) and img.dtype == np.uint8
    assert tuple(_px(img, STATE[:2])) == pr.AGENT_COLOR
    cog = geo.cog_world(STATE[2:5])
    assert tuple(_px(img, cog)) == pr.BLOCK_COLOR
    goal_cog = geo.cog_world(geo.GOAL_POSE)
    assert tuple(_px(img, goal_cog)) == pr.GOAL_COLOR
    assert tuple(_px(img, (256.0, 470.0))) == pr.WHITE


def test_block_pixel_area_matches_geometry():
    img = pr.render_state(STATE, 256).astype(int)
    # Only the block lives in the top-right quarter; count pixels at least half covered
    # (darker than halfway between white and the fill; the outline is darker still).
    quarter = img[:128, 128:]
    covered = quarter.sum(-1) < (3 * 255 + sum(pr.BLOCK_COLOR)) / 2
    # PIL centres the 2-unit outline on the T's edges, so the drawn T is the geometric T grown
    # by half the outline width (a mitred buffer of 1 unit).
    expected = geo.t_shape(STATE[2:5]).buffer(1.0, join_style="mitre").area * (256 / 512) ** 2
    assert abs(covered.sum() - expected) / expected < 0.03


def test_target_drawn_only_when_asked():
    r = pr.PushTRenderer(128)
    plain = r.render(STATE)
    marked = r.render(STATE, target=(300.0, 300.0))
    diff = np.argwhere(np.any(plain != marked, axis=-1))
    assert len(diff) > 0
    # all changed pixels sit around the target (300, 300) -> pixel (75, 75)
    assert np.abs(diff - 75).max() <= 4


def test_observation_never_shows_target():
    env = PushTEnv(obs_type="pixels", render_mode="rgb_array", render_size=128)
    env.reset(seed=0)
    obs, *_ = env.step([300.0, 300.0])
    def reddish(img):
        r, g, b = np.moveaxis(img.astype(int), -1, 0)
        return (r > g + 60) & (r > b + 60)

    assert obs.shape == (96, 96, 3) and not reddish(obs).any()
    view = env.render()
    assert view.shape == (128, 128, 3)
    assert reddish(view).sum() >= 5


def test_env_pixels_match_render_state():
    env = PushTEnv(obs_type="pixels_agent_pos", obs_size=(80, 112))
    obs, info = env.reset(seed=7)
    assert obs["pixels"].shape == (80, 112, 3)
    np.testing.assert_array_equal(obs["agent_pos"], info["agent_pos"])
    state = np.r_[info["agent_pos"], info["block_pose"]]
    np.testing.assert_array_equal(obs["pixels"], pr.render_state(state, (80, 112)))


def test_render_mode_none_returns_none():
    env = PushTEnv()
    env.reset(seed=0)
    assert env.render() is None


def test_bad_render_input():
    with pytest.raises(ValueError, match="finite"):
        pr.render_state([1.0, 2.0, np.nan, 4.0, 5.0])
    with pytest.raises(ValueError, match="size"):
        pr.PushTRenderer((96,))


# ------------------------------------------------------------------------------------------
# matplotlib figures (coursekit.viz.pusht_plots)
# ------------------------------------------------------------------------------------------
def test_draw_scene_places_patches_from_geometry():
    from matplotlib.figure import Figure

    from coursekit.viz import pusht_plots as pp

    ax = Figure().add_subplot()
    art = pp.draw_scene(ax, STATE, target=(10.0, 20.0))
    np.testing.assert_allclose(art.block.get_xy()[:8], geo.block_outline(STATE[2:5]))
    assert art.agent.center == (80.0, 430.0) and art.agent.radius == geo.AGENT_RADIUS
    assert ax.get_ylim() == (512.0, 0.0)  # y down like the images
    moved = STATE + [5, 5, 10, -10, 0.3]
    art.update(moved, target=None)
    np.testing.assert_allclose(art.block.get_xy()[:8], geo.block_outline(moved[2:5]))


def test_rollout_animation_and_html():
    from coursekit.viz import pusht_plots as pp

    states = np.array([STATE + [i, 0, 0, 0, 0.05 * i] for i in range(5)])
    html = pp.rollout_jshtml(states, actions=states[:, :2], coverage=np.linspace(0, 1, 5), stride=2)
    assert "<script" in html and html.count("data:image/png;base64") == 3  # frames 0, 2, 4
    # the final state is always shown, even when the stride skips it
    assert pp.rollout_jshtml(states, stride=3).count("data:image/png;base64") == 3  # 0, 3, 4
    with pytest.raises(ValueError, match="coverage"):
        pp.animate_rollout(states, coverage=np.zeros(3))


def test_coverage_and_trajectory_figures():
    from coursekit.viz import pusht_plots as pp

    c = np.array([0.0, 0.3, 0.96])
    fig = pp.plot_coverage(c)
    ax = fig.axes[0]
    np.testing.assert_array_equal(ax.lines[0].get_ydata(), c)
    assert ax.lines[1].get_ydata()[0] == pytest.approx(0.95)
    paths = [np.array([[10.0, 10.0], [50.0, 60.0]]), np.array([[10.0, 10.0], [90.0, 20.0]])]
    fig = pp.plot_trajectories(paths, scene_state=STATE, labels=["cw", "ccw"])
    lines = [ln for ln in fig.axes[0].lines if len(ln.get_xdata()) == 2]
    assert len(lines) == 2
    assert [t.get_text() for t in fig.axes[0].get_legend().get_texts()] == ["cw", "ccw"]
    with pytest.raises(ValueError, match="labels"):
        pp.plot_trajectories(paths, labels=["one"])
