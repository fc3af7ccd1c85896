"""Demonstrations as people give them: the PushT planner with a person's variety.

Chi et al. (2023, Sec. 5.1) train on 206 HUMAN demonstrations of PushT. A person does not
replay one optimiser: where two pushes are about as good they pick either, they go round the
long way now and then, they move faster or slower from one demonstration to the next, and
they pause to look. The scripted planner (``pusht_planner``) has only one of these: a coin
between clockwise and anticlockwise when both routes are within ``route_tolerance`` of each
other. :class:`PersonStyle` adds the rest, each as a seeded draw, so that the demonstrations
leave the same state in different directions much more often (``coursekit.data.multimodality``
measures how often):

- **choice** (at every re-plan): every checked push whose score is within
  ``choice_tolerance`` of the best one's is an equally good choice; a draw picks one;
- **routes**: a wider ``route_tolerance``, so the side coin is tossed from more places;
- **pace** (per episode): travel and push speeds scaled by one factor drawn from ``pace``;
- **pauses**: before a travel leg, with probability ``pause_prob``, the hand holds still for a
  number of steps drawn from ``pause_steps`` (the target stays on the pusher).

Everything is a function of the episode seed (its own random stream), so the same seed gives
the same demonstration. ``coursekit collect pusht --style person`` writes such a data set.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from coursekit.experts.pusht_config import ExpertConfig

STYLE_STREAM = 0x9E75
"""Mixed into a style's random stream so it never shares one with the reset, coin or noise."""


@dataclass(frozen=True)
class PersonStyle:
    """How a person's demonstrations vary where the scripted planner's do not."""

    choice_tolerance: float = 0.3
    """Checked pushes scoring at least (1 - this) x the best score are equally good; a draw picks one (0: the best)."""
    route_tolerance: float = 0.6
    """Replaces ExpertConfig.route_tolerance: routes this close in length are a real two-way choice."""
    pace: tuple[float, float] = (0.7, 1.3)
    """Range of the per-episode factor on travel, turn and push speeds and the travel acceleration (uniform)."""
    pause_prob: float = 0.15
    """Probability of a pause before each travel leg."""
    pause_steps: tuple[int, int] = (2, 6)
    """Shortest and longest pause, in 10 Hz steps (uniform over the integers between)."""

    def __post_init__(self) -> None:
        if not 0.0 <= self.choice_tolerance < 1.0:
            raise ValueError(f"choice_tolerance must be in [0, 1), got {self.choice_tolerance!r}")
        if not (math.isfinite(self.route_tolerance) and self.route_tolerance >= 0):
            raise ValueError(f"route_tolerance must be >= 0, got {self.route_tolerance!r}")
        lo, hi = self.pace
        if not (0.2 <= lo <= hi <= 3.0):
            raise ValueError(f"pace must be (low, high) with 0.2 <= low <= high <= 3, got {self.pace!r}")
        if not 0.0 <= self.pause_prob <= 1.0:
            raise ValueError(f"pause_prob must be in [0, 1], got {self.pause_prob!r}")
        short, long = self.pause_steps
        if not (isinstance(short, int) and isinstance(long, int) and 1 <= short <= long <= 50):
            raise ValueError(f"pause_steps must be (shortest, longest) ints with 1 <= shortest <= longest <= 50, "
                             f"got {self.pause_steps!r}")


STYLES: dict[str, PersonStyle | None] = {"scripted": None, "person": PersonStyle()}
"""``coursekit collect pusht --style NAME``: the planner as it is, or with a person's variety."""


class StyleDraws:
    """One episode's draws of a :class:`PersonStyle` (seeded by the episode's seed)."""

    def __init__(self, style: PersonStyle, seed: int):
        self.style = style
        self.rng = np.random.default_rng([STYLE_STREAM, int(seed)])
        self.pace = float(self.rng.uniform(*style.pace))

    def episode_config(self, base: ExpertConfig) -> ExpertConfig:
        """``base`` at this episode's pace and with the style's route tolerance."""
        p = self.pace
        return dataclasses.replace(base, travel_speed=base.travel_speed * p, travel_accel=base.travel_accel * p,
                                   turn_speed=base.turn_speed * p, push_speed=base.push_speed * p,
                                   route_tolerance=self.style.route_tolerance)

    def pick(self, scored: Sequence) -> object:
        """One of ``scored`` (objects with a ``score``, best first or not): uniformly among those
        within ``choice_tolerance`` of the best score. With one candidate, that one."""
        best = max(s.score for s in scored)
        floor = best - self.style.choice_tolerance * abs(best)
        near = [s for s in scored if s.score >= floor]
        return near[int(self.rng.integers(len(near)))]

    def pause(self) -> int:
        """Steps to hold still before the next travel leg (0: no pause)."""
        if self.rng.random() >= self.style.pause_prob:
            return 0
        short, long = self.style.pause_steps
        return int(self.rng.integers(short, long + 1))


Picker = Callable[[Sequence], object]
"""Chooses one scored candidate push; the planner's own choice is the best score."""
