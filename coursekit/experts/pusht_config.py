"""Settings of the scripted PushT expert (``pusht_planner``), one documented field each."""

from __future__ import annotations

from dataclasses import dataclass

from coursekit.tasks.pusht import PUSHT


@dataclass
class ExpertConfig:
    """Settings of the scripted PushT expert (pixels are world units, steps are 10 Hz env steps)."""

    max_steps: int = PUSHT.max_steps
    """Give up after this many env steps (default: the evaluation protocol's episode length)."""
    travel_speed: float = 35.0
    """Speed limit of the pusher's target while travelling (px per step)."""
    travel_accel: float = 12.0
    """How fast the target may speed up or brake while travelling (px per step^2)."""
    turn_speed: float = 15.0
    """Target speed at a right-angle turn of a route (the lagging pusher cuts corners)."""
    travel_margin: float = 6.0
    """Clearance kept between the pusher's edge and the T while travelling (px)."""
    approach_gap: float = 9.0
    """Gap between the pusher's edge and the contact at the end of a route (px)."""
    standoff_gap: float = 3.0
    """Gap at which the pusher stops short of the contact before pushing in (px)."""
    push_speed: float = 20.0
    """Fastest target speed while pushing (px per step); shorter pushes go slower."""
    push_depths: tuple[float, ...] = (3.0, 6.0, 11.0, 18.0, 28.0, 42.0, 60.0, 85.0, 120.0)
    """How far past first touch a push may drive the pusher (px); candidates try each."""
    contact_spacing: float = 10.0
    """Spacing of candidate contacts along the T's edges (px)."""
    corner_directions: int = 3
    """Push directions tried strictly inside each convex corner's 90 degree range."""
    n_verify: int = 6
    """Candidate pushes replayed in the scratch simulator before choosing one."""
    hold_steps: int = 1
    """Steps the push target holds still at the end of a push (the pusher catches up)."""
    route_tolerance: float = 0.35
    """Clockwise and anticlockwise routes whose lengths differ by less than this fraction of the
    shorter one count as a real two-way choice: a seeded coin picks the side."""
    rest_steps: int = 5
    """Steps at rest (target = pusher position) recorded after success."""
    final_coverage: float = 0.96
    """Coverage the T must still have after the rest steps for a push to count as the last one
    (at least the success threshold 0.95; higher ends demonstrations deeper inside success)."""
    max_settle_steps: int = 20
    """At most this many steps waiting for an overlapping reset to settle."""

    def __post_init__(self) -> None:
        for name in ("travel_speed", "travel_accel", "turn_speed", "push_speed", "contact_spacing"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("max_steps", "n_verify"):
            if not getattr(self, name) >= 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)!r}")
        for name in ("hold_steps", "rest_steps", "max_settle_steps", "corner_directions"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if not 0 <= self.standoff_gap < self.approach_gap:
            raise ValueError(f"need 0 <= standoff_gap < approach_gap, got {self.standoff_gap!r}, {self.approach_gap!r}")
        if not 0 < self.travel_margin <= self.approach_gap:
            raise ValueError(f"need 0 < travel_margin <= approach_gap, got {self.travel_margin!r} "
                             f"(approach_gap {self.approach_gap!r})")
        if self.turn_speed > self.travel_speed:
            raise ValueError(f"turn_speed {self.turn_speed!r} exceeds travel_speed {self.travel_speed!r}")
        if not self.push_depths or min(self.push_depths) <= 0:
            raise ValueError(f"push_depths must be a non-empty tuple of positive depths, got {self.push_depths!r}")
        if not 0.95 <= self.final_coverage < 1.0:
            raise ValueError(f"final_coverage must be in [0.95, 1), got {self.final_coverage!r}")
        if self.route_tolerance < 0:
            raise ValueError(f"route_tolerance must be >= 0, got {self.route_tolerance!r}")
        self.push_depths = tuple(float(d) for d in self.push_depths)
