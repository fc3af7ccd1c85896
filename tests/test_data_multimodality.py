"""The two-way measure (coursekit.data.multimodality) on data whose answer is known by construction."""

import math

import numpy as np
import pytest

from coursekit.data.episodes import EpisodeDataset
from coursekit.data.multimodality import MultimodalityConfig, Neighbourhoods, is_two_way, two_way_fraction


def _fan(directions_deg, n_per_direction=4, steps=20):
    """Episodes that start at the same state (pusher at 100, 100; block fixed) and travel in a
    straight line along each of ``directions_deg``; every row is in the travel phase."""
    episodes = []
    for k, deg in enumerate(np.repeat(directions_deg, n_per_direction)):
        d = np.array([math.cos(math.radians(deg)), math.sin(math.radians(deg))])
        start = np.array([100.0, 100.0]) + 0.01 * k  # distinct episodes, same place
        pusher = start + 3.0 * np.arange(steps)[:, None] * d  # (T, 2): 3 px per step
        state = np.column_stack([pusher, np.full((steps, 2), 300.0), np.zeros(steps)])
        action = pusher + 3.0 * d
        episodes.append({"state": state, "action": action, "phase": np.ones(steps, np.int8)})
    return EpisodeDataset.from_episodes(episodes)


def test_one_direction_is_never_two_way():
    m = two_way_fraction(_fan([0.0, 10.0]), MultimodalityConfig(n_queries=50))
    assert m.n_supported > 0 and m.fraction == 0.0


def test_opposite_directions_from_one_start_are_two_way():
    cfg = MultimodalityConfig(n_queries=400, radius=5.0)
    m = two_way_fraction(_fan([0.0, 180.0]), cfg)
    # Only the first rows of the fan share a neighbourhood (the branches separate at 6 px per step):
    # every supported query is there, and it is two-way.
    first = np.isin(m.query_rows % 20, [0])
    assert m.n_supported >= 1 and m.fraction == 1.0
    assert (m.two_way[~first] == -1).all()


def test_neighbourhoods_built_once_give_the_same_measure():
    cfg = MultimodalityConfig(n_queries=400, radius=5.0)
    data = _fan([0.0, 180.0])
    again = two_way_fraction(Neighbourhoods(data, cfg))
    m = two_way_fraction(data, cfg)
    assert (again.fraction, again.lo, again.hi) == (m.fraction, m.lo, m.hi)
    assert np.array_equal(again.two_way, m.two_way) and np.array_equal(again.query_rows, m.query_rows)
    with pytest.raises(ValueError, match="differs from the Neighbourhoods' own"):
        two_way_fraction(Neighbourhoods(data, cfg), MultimodalityConfig(radius=9.0))


def test_is_two_way_follows_its_definition():
    cfg = MultimodalityConfig()
    east, west, north = [20.0, 0.0], [-20.0, 0.0], [0.0, 20.0]
    assert not is_two_way(np.array([east] * 8), cfg)
    assert is_two_way(np.array([east] * 6 + [west] * 2), cfg)  # 2 of 8 = 25 % go another way
    assert not is_two_way(np.array([east] * 7 + [west] * 1), cfg)  # 1 of 8: below 25 % (and below two)
    assert not is_two_way(np.array([east] * 4 + [north] * 4), cfg)  # 90 degrees apart: not MORE than split_deg
    assert not is_two_way(np.array([east] * 4 + [[0.0, 1.0]] * 6), cfg)  # the others stay put (< still_px)


@pytest.mark.parametrize("bad", [{"radius": 0.0}, {"min_fraction": 0.6}, {"mode_deg": 100.0}, {"horizon": 0}])
def test_bad_config_names_the_field(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        MultimodalityConfig(**bad)
