"""A scripted PushT expert: plan a push, walk round the T to it, push, repeat, then rest.

The paper's 206 human demonstrations cannot be downloaded, so the course makes its own with
this planner, built on the task's own physics (``pusht_push_model``): contact is rare, so
sampling MPC on raw pusher targets cannot plan "go round, then push".
``benchmarks/bench_pusht_expert.py`` measures its success, speed and route choices. One episode:

1. settle    if the reset left the T in a wall or under the pusher, hold still until the
             physics has pushed them apart, then step out of the T's way;
2. plan      rank every candidate push (contact x depth) by the drop in log pose error per
             env step it costs, travel included, and check the best few in a scratch copy of
             the simulator (``pusht_push_search``, with the model of ``pusht_push_model``);
3. travel    straight to the push's approach point if the line is clear, else round the T
             (``pusht_routes``); when clockwise and anticlockwise are about equally long, a
             seeded coin picks the side: the demonstrations' built-in multimodality. Each
             route is replayed first and slowed down until it does not brush the block;
4. push      stop short of the contact, re-check the push from the real state, push in along
             the contact normal and hold; then either keep pushing the same contact or back
             off, whichever the simulator says is better; repeat from 2 until coverage > 0.95
             at a moment when the T will stay put (``final_coverage`` after resting);
5. rest      a few steps with the target on the pusher's own position, so that learned
             policies see when to stop (demonstrations that end at the first step over 0.95
             teach a policy never to stop: near the goal it keeps pushing the block away).

Targets move at most ``travel_speed`` px per 10 Hz step and brake before turns and at the
end, the way a hand would. Everything is deterministic given the reset seed and coin seed.
``collect_dataset`` (``coursekit collect pusht``) turns episodes into an ``EpisodeDataset``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict
from typing import TYPE_CHECKING

import numpy as np

from coursekit.envs import pusht_geometry as geo
from coursekit.envs.pusht_geometry import local_to_world, world_to_local
from coursekit.experts.pusht_clearance import point_distance
from coursekit.experts.pusht_config import ExpertConfig
from coursekit.experts.pusht_person import PersonStyle, StyleDraws
from coursekit.experts.pusht_recording import PHASE_NAMES, PUSH, REST, SETTLE, TRAVEL, EpisodeRecord, Recorder
from coursekit.experts.pusht_push_search import Push, PushSearch
from coursekit.experts.pusht_routes import ANTICLOCKWISE, CLOCKWISE, STRAIGHT, speed_profile_targets
from coursekit.tasks.pusht import PUSHT

if TYPE_CHECKING:
    from coursekit.data import EpisodeDataset

__all__ = ["TWO_WAY_START", "EpisodeRecord", "ExpertConfig", "PushTExpert", "collect_dataset", "noise_tag",
           "parse_action_noise"]

EXPERT_NAME = "coursekit.experts.pusht_planner"
EXPERT_VERSION = "1"
COIN_STREAM = 0xC01
"""Mixed into the coin's seed so that the coin never shares a random stream with the reset."""
NOISE_STREAM = 0xDA27
"""Mixed into the execution-noise seed (``action_noise``) for the same reason."""

TWO_WAY_START = (100.0, 256.0, 300.0, 256.0, 3 * math.pi / 4)
"""A reset state [ax, ay, bx, by, angle] (``reset_to_state``, legacy order) where the T stands
between the pusher and the push it wants, with both ways round about equally long: the coin
decides, so expert runs from this one start split between clockwise and anticlockwise."""

class Coin:
    """The seeded coin that picks a side when both ways round are about equally good.

    Antithetic pairs (a standard variance-reduction trick, a deliberate choice): seeds 2j and
    2j + 1 share one random stream and read it as u and 1 - u, so in any pair of episodes that
    both toss, one goes each way. Each episode's coin is still fair (u is uniform), and a
    dataset of consecutive seeds stays close to a 50/50 split instead of drifting by chance.
    """

    def __init__(self, seed: int):
        self._rng = np.random.default_rng([COIN_STREAM, int(seed) // 2])
        self._flip = int(seed) % 2 == 1

    def heads(self) -> bool:
        """One toss: True with probability 1/2."""
        u = float(self._rng.random())
        return (1.0 - u if self._flip else u) < 0.5


class PushTExpert:
    """The planner. ``run_episode(env, seed)`` plays one episode in ``env`` and records it."""

    def __init__(self, config: ExpertConfig | None = None, style: PersonStyle | None = None):
        self.config = config or ExpertConfig()
        self.style = style
        """None: the planner's own demonstrations; a PersonStyle: a person's variety (``pusht_person``)."""
        self.search = PushSearch(self.config)
        self.routes = self.search.routes

    # ----------------------------------------------------------------------------------------
    # Travel
    # ----------------------------------------------------------------------------------------
    def escape_point(self, state: np.ndarray) -> np.ndarray | None:
        """World point where a pusher standing (or stuck) closer to the T than the travel
        clearance gets out by the shortest straight move; None when it is clear already."""
        pose = state[2:5]
        start = world_to_local(state[:2], pose)
        clearance = self.routes.clearance + 1.0
        if float(point_distance(start)) >= clearance:
            return None
        angles = np.linspace(0.0, 2 * math.pi, 32, endpoint=False)
        dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # (32, 2)
        reach = np.arange(1.0, 200.0)  # (R,) move lengths tried
        clear = point_distance(start + reach[None, :, None] * dirs[:, None, :]) >= clearance  # (32, R)
        # Out for good: the first length after which the ray stays clear.
        last_blocked = np.where(clear.all(1), -1, len(reach) - 1 - np.argmin(clear[:, ::-1], axis=1))  # (32,)
        out = np.minimum(last_blocked + 1, len(reach) - 1)
        best = int(np.argmin(np.where(clear[:, -1], reach[out], np.inf)))
        return local_to_world(start + reach[out[best]] * dirs[best], pose)

    def choose_sides(self, state: np.ndarray, push: Push, coin: Coin) -> tuple[list[str], dict | None]:
        """Sides to try, preferred first, and the coin toss made (None if there was no real
        choice): clockwise and anticlockwise within ``route_tolerance`` of each other."""
        pose = state[2:5]
        lengths = self.routes.lengths(pose, world_to_local(state[:2], pose),
                                      self.search.approach_local[push.contact][None])
        straight, cw, ccw = lengths[:, 0]
        if np.isfinite(straight):
            return [STRAIGHT], None
        if np.isfinite(cw) and np.isfinite(ccw):
            if abs(cw - ccw) <= self.config.route_tolerance * min(cw, ccw):
                side = CLOCKWISE if coin.heads() else ANTICLOCKWISE
                other = ANTICLOCKWISE if side == CLOCKWISE else CLOCKWISE
                return [side, other], {"side": side, "lengths": [float(cw), float(ccw)]}
            return ([CLOCKWISE, ANTICLOCKWISE] if cw < ccw else [ANTICLOCKWISE, CLOCKWISE]), None
        return [s for s, length in ((CLOCKWISE, cw), (ANTICLOCKWISE, ccw)) if np.isfinite(length)], None

    def plan_travel(self, state: np.ndarray, push: Push, sides: list[str]) -> tuple[np.ndarray, str, bool]:
        """Targets (T, 2) from the pusher to ``push.standoff`` along the first side whose replay
        leaves the block untouched, slowing down up to twice; returns (targets, side, touched).

        Right after a push the lagging pusher is often still within a pixel of the T; routes may
        leave along that gap. Only if every such try touches the block does the pusher first
        step straight out to the travel clearance, stop, and then set off.
        """
        cfg = self.config
        pose = state[2:5]
        fallback = None
        for escape in (False, True):
            start, prefix = state[:2], np.empty((0, 2))
            if escape:
                exit_point = self.escape_point(state)
                if exit_point is None:
                    break
                prefix = speed_profile_targets(np.stack([start, exit_point]), cfg.turn_speed, cfg.travel_accel,
                                               cfg.turn_speed)
                start = exit_point
            for side in sides:
                try:
                    route = self.routes.route(pose, world_to_local(start, pose),
                                              self.search.approach_local[push.contact], side)
                except ValueError:  # that side is closed off from this start
                    continue
                points = np.concatenate([route.points, push.standoff[None]])  # (K+1, 2)
                for slow in (1.0, 0.6, 0.35):
                    targets = np.concatenate([prefix, speed_profile_targets(
                        points, cfg.travel_speed * slow, cfg.travel_accel * slow, cfg.turn_speed * slow)])
                    if not self._bumps(state, targets):
                        return targets, side, False
                    fallback = (targets, side) if fallback is None else fallback
        if fallback is None:  # no route at all (never seen): go straight and accept the touch
            fallback = (speed_profile_targets(np.stack([state[:2], push.standoff]), cfg.turn_speed,
                                              cfg.travel_accel, cfg.turn_speed), STRAIGHT)
        return fallback[0], fallback[1], True

    def _bumps(self, state: np.ndarray, targets: np.ndarray) -> bool:
        """Whether following ``targets`` from ``state`` moves the block at all. Compared with
        the block left alone (pusher far away): a block settling out of a wall keeps creeping
        for a while, and that is not a bump."""
        end, _ = self.search.simulate(state, targets)
        if np.abs(end[2:5] - state[2:5]).max() < 1e-9:
            return False
        far = np.concatenate([state[2:4] + 4 * geo.WORLD_SIZE, state[2:5]])
        alone, _ = self.search.simulate(far, np.repeat(far[None, :2], len(targets), axis=0))
        return bool(np.abs(end[2:5] - alone[2:5]).max() >= 1e-6)

    # ----------------------------------------------------------------------------------------
    # One episode
    # ----------------------------------------------------------------------------------------
    def run_episode(self, env, seed: int | None = None, coin_seed: int | None = None,
                    reset_state=None, action_noise: float = 0.0) -> EpisodeRecord:
        """Reset ``env`` (a ``PushTEnv``) with ``seed`` (or to ``reset_state`` (5,)) and solve it.

        ``coin_seed`` (default: ``seed``) seeds the coin that picks between equally good sides.
        ``action_noise`` > 0: DART-style demonstrations (Laskey et al. 2017): the env executes
        the expert's target plus Gaussian noise of this standard deviation (px, per axis, per
        step, seeded by ``coin_seed``) while the record keeps the expert's clean target. The
        expert re-plans from the real state after every push, so the episode shows it
        correcting the drift: the recovery data that clean demonstrations lack.
        """
        if not (math.isfinite(action_noise) and action_noise >= 0):
            raise ValueError(f"action_noise must be a finite standard deviation >= 0 (px), got {action_noise!r}")
        cfg, search = self.config, self.search
        options = None if reset_state is None else {"reset_to_state": np.asarray(reset_state, dtype=np.float64)}
        _, info = env.reset(seed=seed, options=options)
        stream_seed = coin_seed if coin_seed is not None else (seed if seed is not None else 0)
        coin = Coin(stream_seed)
        noise = None
        if action_noise > 0:
            rng = np.random.default_rng([NOISE_STREAM, int(stream_seed)])
            noise = lambda: rng.normal(0.0, action_noise, size=2)  # noqa: E731  (px, per axis)
        draws = None if self.style is None else StyleDraws(self.style, stream_seed)
        planner = self if draws is None else PushTExpert(draws.episode_config(cfg))  # this episode's pace
        ep = Recorder(env, info["coverage"], cfg.max_steps, search.rests_successfully, noise)
        return planner._play(env, ep, coin, draws)

    def _play(self, env, ep: Recorder, coin: Coin, draws: StyleDraws | None) -> EpisodeRecord:
        """Settle, then plan / travel / push until done, then rest (module docstring, steps 1-5)."""
        cfg, search = self.config, self.search
        pick = None if draws is None else draws.pick
        self._settle(env, ep)
        choices: list[dict] = []
        bumps = 0
        pushed: Push | None = None  # the push just made, pusher still against the T
        while not ep.done:
            state = env.get_state()
            if pushed is None:
                plan = search.plan(state, pick=pick)
            else:  # push on, or back off and push elsewhere: the simulator decides
                backed_off, _ = search.simulate(state, pushed.back_off)
                plan = search.plan(backed_off, extra_steps=len(pushed.back_off), pick=pick)
                more = search.continuation(state, pushed)
                if more is not None and (plan is None or more.score >= plan.score):
                    ep.follow(more.push_in, PUSH)
                    pushed = more
                    continue
                ep.follow(pushed.back_off, PUSH)
                pushed = None
                state = env.get_state()
            if plan is None or ep.done:
                break
            if np.linalg.norm(state[:2] - plan.standoff) > 1.0:
                pause = 0 if draws is None else draws.pause()
                if pause:  # a person stops to look before setting off
                    ep.follow(np.repeat(state[None, :2], pause, axis=0), TRAVEL)
                    state = env.get_state()
                    if ep.done:
                        break
                sides, toss = self.choose_sides(state, plan, coin)
                if not sides:
                    break
                targets, side, touched = self.plan_travel(state, plan, sides)
                if toss is not None:
                    choices.append({"step": ep.n_steps, **toss, "taken": side})
                bumps += int(touched)
                ep.follow(targets, TRAVEL)
                if ep.done:
                    break
            push = search.recheck(env.get_state(), plan)
            if push is None:  # the plan no longer helps: step back and think again
                ep.follow(speed_profile_targets(np.stack([env.get_state()[:2], plan.approach]),
                                                cfg.travel_speed, cfg.travel_accel, cfg.turn_speed), TRAVEL)
                continue
            ep.follow(push.push_in, PUSH)
            pushed = push
        if ep.success_step is not None:  # 5. rest
            for _ in range(cfg.rest_steps):
                ep.step(env.get_state()[:2], REST, force=True)
        return ep.record(choices, bumps)

    def _settle(self, env, ep: Recorder) -> None:
        """Hold still while the physics separates an overlapping reset, then step clear."""
        cfg = self.config
        for _ in range(cfg.max_settle_steps):
            state = env.get_state()
            end, _ = self.search.simulate(state, state[None, :2])
            if np.abs(end[2:5] - state[2:5]).max() < 0.01:  # at rest to the eye
                break
            ep.step(state[:2], SETTLE)
        state = env.get_state()
        exit_point = self.escape_point(state)
        if exit_point is not None:
            ep.follow(speed_profile_targets(np.stack([state[:2], exit_point]), cfg.travel_speed,
                                            cfg.travel_accel, cfg.turn_speed), SETTLE)


# --------------------------------------------------------------------------------------------
# A dataset of demonstrations
# --------------------------------------------------------------------------------------------
def parse_action_noise(text: str) -> tuple[float, ...]:
    """Noise levels from the command line: '5' -> (5.0,), '0,5' -> (0.0, 5.0) (px)."""
    try:
        return tuple(float(v) for v in str(text).split(","))
    except ValueError:
        raise ValueError(f"--action-noise must be a number or a comma list of numbers (px), got {text!r}") from None


def noise_tag(action_noise: Sequence[float]) -> str:
    """File-name suffix for DART noise levels: '' for clean data, '_noise0-5' for (0, 5)."""
    return "" if set(action_noise) <= {0.0} else "_noise" + "-".join(f"{float(v):g}" for v in action_noise)


def collect_dataset(n_episodes: int, seed: int, progress: bool = True, config: ExpertConfig | None = None,
                    action_noise: float | Sequence[float] = 0.0, style: PersonStyle | None = None) -> EpisodeDataset:
    """Run the expert on the seeded reference resets ``seed, seed + 1, ...`` and collect
    ``n_episodes`` successful demonstrations (a failed seed, rare, is skipped and listed in
    ``meta["failed_seeds"]``). Deterministic: the same arguments give identical arrays.

    ``action_noise``: DART-style execution noise (px, see ``PushTExpert.run_episode``); a
    sequence is cycled over the attempts, e.g. ``(0, 10)`` alternates clean and noisy
    episodes. Each episode's level is in ``meta["episode_noise"]``. ``style``: demonstrations
    with a person's variety (``pusht_person.PersonStyle``; None: the planner's own), kept in
    ``meta["expert_style"]``.

    Arrays (N steps over all episodes; row t is the state BEFORE action t):
        "state"    (N, 5) float64 [agent_x, agent_y, block_x, block_y, block_angle UNWRAPPED]
        "action"   (N, 2) float64 pusher target (x, y)
        "coverage" (N,)   float64 coverage of the row's state
        "phase"    (N,)   int8 0 settle, 1 travel, 2 push, 3 rest (see ``PHASE_NAMES``)
    Meta: env_id, obs_type, expert, expert_version, expert_config, seed, n_episodes,
    action_noise, episode_noise, episode_seeds, failed_seeds, success_steps (first coverage > 0.95), finish_steps (where the
    rest begins; see ``EpisodeRecord``), route_choices (per episode, one dict per coin
    toss), rest_steps, coursekit_version. Pixel observations can be rendered from the stored
    states afterwards (``coursekit.envs.pusht_render``).
    """
    from coursekit.data import EpisodeDataset
    from coursekit.envs.pusht import PushTEnv

    if isinstance(n_episodes, bool) or not isinstance(n_episodes, (int, np.integer)) or n_episodes < 1:
        raise ValueError(f"n_episodes must be a positive int, got {n_episodes!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative int, got {seed!r}")
    levels = [float(action_noise)] if np.isscalar(action_noise) else [float(v) for v in action_noise]
    if not levels or not all(math.isfinite(v) and v >= 0 for v in levels):
        raise ValueError(f"action_noise must be a standard deviation >= 0 (px) or a non-empty sequence of them, "
                         f"got {action_noise!r}")
    expert = PushTExpert(config, style)
    env = PushTEnv(obs_type="state", max_episode_steps=expert.config.max_steps)
    solved, failed = _solved_episodes(expert, env, int(n_episodes), int(seed), levels, progress)
    episodes = [{"state": rec.states, "action": rec.actions, "coverage": rec.coverage, "phase": rec.phases}
                for _, _, rec in solved]
    return EpisodeDataset.from_episodes(episodes, _dataset_meta(expert, int(seed), levels, solved, failed))


def _solved_episodes(expert: PushTExpert, env, n_episodes: int, seed: int, levels: list[float],
                     progress: bool) -> tuple[list[tuple[int, float, EpisodeRecord]], list[int]]:
    """Run the resets ``seed, seed + 1, ...`` (noise levels cycled) until ``n_episodes`` are solved:
    (reset seed, noise level, record) of each solved one, and the seeds that failed."""
    from tqdm.auto import tqdm

    solved, failed = [], []
    max_attempts = 2 * n_episodes + 10
    with tqdm(total=n_episodes, desc="PushT expert", unit="episode", disable=not progress) as bar:
        for attempt in range(max_attempts):
            if len(solved) == n_episodes:
                break
            episode_seed, level = seed + attempt, levels[attempt % len(levels)]
            rec = expert.run_episode(env, episode_seed, action_noise=level)
            if rec.success_step is None:
                failed.append(episode_seed)
                continue
            solved.append((episode_seed, level, rec))
            bar.update(1)
    if len(solved) < n_episodes:
        raise RuntimeError(f"the expert solved only {len(solved)} of {max_attempts} resets from seed {seed}; "
                           f"failed seeds: {failed[:20]}")
    return solved, failed


def _dataset_meta(expert: PushTExpert, seed: int, levels: list[float], solved: list[tuple[int, float, EpisodeRecord]],
                  failed: list[int]) -> dict:
    """The dataset's meta (the keys ``collect_dataset`` lists): how and from which resets it was made."""
    import coursekit

    return {
        "env_id": PUSHT.gym_id, "obs_type": "state",
        "expert": EXPERT_NAME, "expert_version": EXPERT_VERSION,
        "expert_config": asdict(expert.config),
        "expert_style": None if expert.style is None else asdict(expert.style),
        "seed": seed, "n_episodes": len(solved),
        "action_noise": levels, "episode_noise": [level for _, level, _ in solved],
        "episode_seeds": [s for s, _, _ in solved], "failed_seeds": failed,
        "success_steps": [rec.success_step for _, _, rec in solved],
        "finish_steps": [rec.finish_step for _, _, rec in solved],
        "route_choices": [rec.route_choices for _, _, rec in solved], "rest_steps": expert.config.rest_steps,
        "phase_names": list(PHASE_NAMES),
        "state_columns": ["agent_x", "agent_y", "block_x", "block_y", "block_angle_unwrapped"],
        "action_columns": ["target_x", "target_y"],
        "coursekit_version": coursekit.__version__,
    }
