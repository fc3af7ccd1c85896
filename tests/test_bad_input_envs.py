"""Bad actions and resets, property-based: a valid one runs, anything else is ONE clear ValueError.

For arbitrary actions (any shape, NaN/inf, strings, None, nested junk) and arbitrary reset
arguments (negative / huge / float / bool seeds, options that are not a dict, unknown keys,
malformed start states), both PushT and the ALOHA arm pair either accept the input exactly when
it is well formed, or raise a ValueError that names the argument — never another exception — and
a refused action leaves the simulation state untouched.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coursekit.envs.pusht import PushTEnv

SETTINGS = settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
junk = st.one_of(st.none(), st.text(max_size=5), st.booleans(), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))


def actions(dim: int):
    """Actions of every kind: right or wrong length, (un)finite, nested, non-numeric."""
    vec = lambda n: st.lists(floats, min_size=n, max_size=n)  # noqa: E731
    return st.one_of(vec(dim), vec(dim), st.lists(floats, min_size=0, max_size=dim + 2), st.lists(vec(dim), min_size=1, max_size=2),
                     st.lists(st.one_of(floats, st.text(max_size=2)), min_size=dim, max_size=dim), junk, floats)


def _well_formed(action, dim: int) -> bool:
    return (isinstance(action, list) and len(action) == dim
            and all(isinstance(x, float) and math.isfinite(x) for x in action))


@pytest.fixture(scope="module")
def pusht():
    env = PushTEnv()
    env.reset(seed=0)
    return env


@SETTINGS
@given(action=actions(2))
def test_pusht_step_accepts_exactly_the_well_formed_actions(pusht, action):
    before = pusht.get_state()
    if _well_formed(action, 2):
        obs, *_ = pusht.step(action)
        assert np.all(np.isfinite(obs))
        return
    with pytest.raises(ValueError, match=r"^action must"):
        pusht.step(action)
    np.testing.assert_array_equal(pusht.get_state(), before)


seeds = st.one_of(st.none(), st.integers(-5, 5), st.integers(2**32 - 2, 2**33), st.floats(0, 10), st.booleans(), st.text(max_size=3))


def _seed_ok(seed) -> bool:
    return seed is None or (isinstance(seed, int) and not isinstance(seed, bool) and 0 <= seed < 2**32)


def _pusht_start_in_world(start) -> bool:
    """Pusher and block (x, y) in [0, 512], |angle| <= 1000 rad, and the block's origin after the legacy reset
    order, (bx + 45 sin a, by + 45 (1 - cos a)) in closed form (centre of gravity (0, 45)), in the world too."""
    ax, ay, bx, by, a = start
    origin = (bx + 45.0 * math.sin(a), by + 45.0 * (1.0 - math.cos(a))) if abs(a) <= 1000 else (-1.0, -1.0)
    return all(0.0 <= v <= 512.0 for v in (ax, ay, bx, by, *origin))


coordinates = st.one_of(st.floats(0, 512), st.floats(-1e13, 1e13), st.sampled_from([-1e-9, 512.000001, 1e12]))
starts = st.tuples(coordinates, coordinates, coordinates, coordinates,
                   st.one_of(st.floats(-7, 7), st.floats(-2000, 2000), st.just(1e12))).map(list)


@SETTINGS
@given(seed=seeds, options=st.one_of(st.none(), junk, st.lists(st.integers(), max_size=2),
                                     st.fixed_dictionaries({"reset_to_state": st.one_of(
                                         st.lists(st.floats(40, 470), min_size=5, max_size=5), starts,
                                         st.lists(floats, max_size=7), junk)}),
                                     st.dictionaries(st.sampled_from(["reset_to_sate", "seed", "state"]), st.integers(),
                                                     min_size=1, max_size=2)))
def test_pusht_reset_accepts_exactly_the_well_formed_arguments(pusht, seed, options):
    start = options.get("reset_to_state") if isinstance(options, dict) else None
    ok = (_seed_ok(seed) and (options is None or (isinstance(options, dict) and set(options) <= {"reset_to_state"}
                                                  and (start is None or (_well_formed(start, 5)
                                                                         and _pusht_start_in_world(start))))))
    if ok:
        obs, info = pusht.reset(seed=seed, options=options)
        assert obs.shape == (5,) and 0.0 <= info["coverage"] <= 1.0
        assert pusht.observation_space.contains(obs), obs  # the first observation lies in the env's own space
        return
    with pytest.raises(ValueError, match=r"^PushTEnv.reset: (seed|options|unknown option)|^options\['reset_to_state'\]"):
        pusht.reset(seed=seed, options=options)


def test_pusht_reset_to_a_state_outside_the_world_is_refused_naming_the_value(pusht):
    before = pusht.get_state()
    with pytest.raises(ValueError, match=r"^options\['reset_to_state'\]: agent x must be in \[0, 512\] \(the world\), "
                                         r"got 1000000000000\.0$"):
        pusht.reset(options={"reset_to_state": [1e12] * 5})
    with pytest.raises(ValueError, match=r"angle must be in \[-1000, 1000\] rad, got 1000000000000\.0"):
        pusht.reset(options={"reset_to_state": [100, 100, 300, 300, 1e12]})
    with pytest.raises(ValueError, match=r"would put the block's origin at \(500\.1, 590\.0\), outside the \[0, 512\] world"):
        pusht.reset(options={"reset_to_state": [100, 100, 500, 500, 3.14]})
    np.testing.assert_array_equal(pusht.get_state(), before)  # a refused reset changes nothing


def test_the_issue_examples_give_one_clear_line(pusht):
    with pytest.raises(ValueError, match=r"options must be None or a dict, got 'str' \(str\)"):
        pusht.reset(options="str")
    with pytest.raises(ValueError, match=r"unknown option\(s\) \['reset_to_sate'\]; known options: 'reset_to_state'"):
        pusht.reset(options={"reset_to_sate": [1, 2, 3, 4, 5]})
    with pytest.raises(ValueError, match=r"seed must be None or an int in \[0, 2\*\*32 - 1\], got -1"):
        pusht.reset(seed=-1)
    with pytest.raises(ValueError, match=r"action must be finite \(no NaN or inf\), got \[nan, 1.0\]"):
        pusht.step([float("nan"), 1.0])


@pytest.fixture(scope="module")
def aloha():
    pytest.importorskip("mujoco")
    from coursekit.envs.aloha import AlohaTransferCubeEnv

    env = AlohaTransferCubeEnv()
    env.reset(seed=0)
    return env


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(action=actions(14))
def test_aloha_step_accepts_exactly_the_well_formed_actions(aloha, action):
    before = aloha.get_physics_state()
    if _well_formed(action, 14):
        obs, *_ = aloha.step(action)
        assert np.all(np.isfinite(obs["qpos"]))
        aloha.reset(seed=0)
        return
    with pytest.raises(ValueError, match=r"^action must"):
        aloha.step(action)
    after = aloha.get_physics_state()
    for key in before:
        np.testing.assert_array_equal(after[key], before[key])


TABLE = ((-0.8, 0.8), (0.1, 1.1), (0.0, 1.0))
"""Where an object may be put (m): over the table box of assets/aloha_pair.xml (centre (0, 0.6, -0.02), half
sizes (0.8, 0.5, 0.02)), up to 1 m above its top."""


def _cube_pose_physical(state) -> bool:
    norm = math.sqrt(sum(q * q for q in state[3:]))
    return all(lo <= v <= hi for v, (lo, hi) in zip(state[:3], TABLE)) and abs(norm - 1.0) <= 0.01


def _unit(q):
    n = math.sqrt(sum(v * v for v in q))
    return [v / n for v in q] if n > 1e-3 else [1.0, 0.0, 0.0, 0.0]


cube_poses = st.tuples(st.floats(-0.9, 0.9), st.floats(0.0, 1.2), st.floats(-0.1, 1.1),
                       st.lists(st.floats(-1, 1), min_size=4, max_size=4).map(_unit)).map(lambda t: [*t[:3], *t[3]])
far_poses = st.lists(st.one_of(st.floats(-1e7, 1e7), st.just(1e6)), min_size=7, max_size=7)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=seeds, options=st.one_of(st.none(), junk, st.fixed_dictionaries({"env_state": st.one_of(
    cube_poses, far_poses, st.lists(floats, min_size=7, max_size=7), st.lists(floats, max_size=8), junk)}),
    st.dictionaries(st.sampled_from(["reset_to_state", "envstate"]), st.integers(), min_size=1, max_size=2)))
def test_aloha_reset_accepts_exactly_the_well_formed_arguments(aloha, seed, options):
    state = options.get("env_state") if isinstance(options, dict) else None
    ok = (_seed_ok(seed) and (options is None or (isinstance(options, dict) and set(options) <= {"env_state"}
                                                  and (state is None or (_well_formed(state, 7)
                                                                         and _cube_pose_physical(state))))))
    if ok:
        obs, _ = aloha.reset(seed=seed, options=options)
        assert obs["qpos"].shape == (14,)
        if state is not None:  # the cube is where it was asked to be (quaternion normalised)
            np.testing.assert_allclose(obs["env_state"][:3], state[:3])
            np.testing.assert_allclose(obs["env_state"][3:], np.array(state[3:]) / np.linalg.norm(state[3:]))
        return
    with pytest.raises(ValueError, match=r"^AlohaTransferCubeEnv.reset: (seed|options|unknown option)|^options\['env_state'\]"):
        aloha.reset(seed=seed, options=options)


def test_aloha_far_or_degenerate_object_poses_are_refused_not_reported_as_success(aloha):
    before = aloha.get_physics_state()
    with pytest.raises(ValueError, match=r"^options\['env_state'\]: the cube at xyz \[1000000\.0, 1000000\.0, 1000000\.0\] m "
                                         r"is outside the workspace over the table \(x in \[-0\.80, 0\.80\], y in \[0\.10, 1\.10\], "
                                         r"z in \[0\.00, 1\.00\] m\)$"):
        aloha.reset(options={"env_state": [1e6] * 7})
    with pytest.raises(ValueError, match=r"the cube's orientation \[qw qx qy qz\] must be a unit quaternion .*\(norm 0\)"):
        aloha.reset(options={"env_state": [0.1, 0.5, 0.02, 0.0, 0.0, 0.0, 0.0]})
    after = aloha.get_physics_state()
    for key in before:
        np.testing.assert_array_equal(after[key], before[key])
    _, info = aloha.reset(options={"env_state": [0.1, 0.5, 0.02, 1.0, 0.0, 0.0, 0.0]})  # the spawn pose: fine
    assert not info["is_success"] and info["stage"] == 0

