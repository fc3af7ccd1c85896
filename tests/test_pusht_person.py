"""A person's variety on top of the PushT planner (coursekit.experts.pusht_person)."""

import numpy as np
import pytest

from coursekit.envs.pusht import PushTEnv
from coursekit.experts.pusht_person import PersonStyle, StyleDraws
from coursekit.experts.pusht_planner import PushTExpert


def _run(style, seed):
    env = PushTEnv(obs_type="state", max_episode_steps=300)
    return PushTExpert(style=style).run_episode(env, seed)


def test_a_style_without_variety_is_the_planner_itself():
    """choice_tolerance 0, the planner's route tolerance, pace 1, no pauses: the same episode, row for row."""
    plain = PersonStyle(choice_tolerance=0.0, route_tolerance=0.35, pace=(1.0, 1.0), pause_prob=0.0)
    for seed in (3, 4):
        a, b = _run(None, seed), _run(plain, seed)
        np.testing.assert_array_equal(a.actions, b.actions)
        np.testing.assert_array_equal(a.states, b.states)


def test_person_episodes_are_seeded_and_differ_from_the_planner():
    style = PersonStyle()
    a, b = _run(style, 7), _run(style, 7)
    np.testing.assert_array_equal(a.actions, b.actions)
    planner = _run(None, 7)
    assert a.success_step is not None
    assert a.actions.shape != planner.actions.shape or not np.array_equal(a.actions, planner.actions)


class _Scored:
    def __init__(self, score):
        self.score = score


def test_pick_draws_only_among_the_near_best():
    draws = StyleDraws(PersonStyle(choice_tolerance=0.3), seed=0)
    cands = [_Scored(1.0), _Scored(0.8), _Scored(0.69), _Scored(-1.0)]
    picked = {id(draws.pick(cands)) for _ in range(200)}
    assert picked == {id(cands[0]), id(cands[1])}  # 0.69 < 0.7 = (1 - 0.3) x best


def test_pace_and_pauses_follow_their_ranges():
    style = PersonStyle(pace=(0.8, 1.2), pause_prob=0.5, pause_steps=(2, 4))
    paces = [StyleDraws(style, s).pace for s in range(200)]
    assert 0.8 <= min(paces) < 0.85 and 1.15 < max(paces) <= 1.2
    pauses = [StyleDraws(style, 0).pause() for _ in range(1)] + [d.pause() for d in [StyleDraws(style, 1)] for _ in range(400)]
    assert set(pauses) <= {0, 2, 3, 4} and 0.4 < np.mean(np.array(pauses) > 0) < 0.6


@pytest.mark.parametrize("bad", [{"choice_tolerance": 1.0}, {"pace": (0.1, 1.0)}, {"pace": (1.2, 1.0)},
                                 {"pause_prob": 1.5}, {"pause_steps": (0, 3)}, {"route_tolerance": float("nan")}])
def test_bad_style_names_the_field(bad):
    field = next(iter(bad))
    with pytest.raises(ValueError, match=field):
        PersonStyle(**bad)


def test_collect_command_records_person_style_demonstrations(tmp_path):
    """`coursekit collect pusht --style person` writes the person-like episodes, tagged as such in the meta."""
    from coursekit.cli import main
    from coursekit.data.episodes import EpisodeDataset

    out = tmp_path / "person.npz"
    assert main(["collect", "pusht", "--episodes", "1", "--seed", "7", "--style", "person", "--out", str(out),
                 "--no-progress"]) == 0
    data = EpisodeDataset.load(out)
    np.testing.assert_array_equal(data.episode(0)["action"], _run(PersonStyle(), 7).actions)
