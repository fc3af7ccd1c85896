"""Commitment at a fork (part of ``bench_claims``): which way do sampled DP chunks and the regression chunk go?

From each two-way start (the expert's first decision is a coin toss), at the reset observation
(history = To copies of it, as at the start of an episode): ``n_samples`` DP chunks (DDIM-10,
torch generator seeded per start) and the regression chunk, each classified by
``coursekit.experts.pusht_two_ways.path_side`` from the pusher's position through the chunk's
actions from the current step on (``pred[To-1:]``): clockwise, anticlockwise, or round neither
side (less than 20 degrees about the T's centre of gravity: heading at the T or staying put).
"""

from __future__ import annotations

import numpy as np


def chunk_sides(chunks: np.ndarray, state: np.ndarray, n_obs_steps: int) -> list[str]:
    """Side of each chunk (B, Tp, 2) seen from the reset ``state`` (5,) [agent xy, block xy, angle]."""
    from coursekit.experts.pusht_two_ways import path_side

    return [path_side(np.concatenate([state[None, :2], c[n_obs_steps - 1:]]), state[2:5]) for c in np.asarray(chunks)]


def commitment(starts: list[int], n_samples: int, load_policy, expert_sides: list[str]) -> list[dict]:
    """Rows {"name", "estimate", "note"} for the results table (see the module docstring);
    ``expert_sides``: the side of the expert's first travel leg from each start."""
    import torch

    from coursekit.data.features import get_features
    from coursekit.envs.pusht import PushTEnv
    from coursekit.stats import mean_estimate, rate_estimate

    if not starts:
        raise ValueError("no two-way starts among the seeds: evaluate more episodes")
    env = PushTEnv(obs_type="state")
    dp, dp_sampling, _ = load_policy("dp_ddim10")
    reg, _, _ = load_policy("regression")
    dp_sides, reg_sides, minority, both = [], [], [], []
    for seed in starts:
        obs, _ = env.reset(seed=int(seed))
        state = np.asarray(env.get_state()[:5])
        sides = {}
        for name, policy, sampling, n in (("dp", dp, dp_sampling, n_samples), ("reg", reg, {}, 1)):
            feats = get_features(policy.config.features)(obs)  # (Do,)
            history = np.repeat(feats[None, None], policy.config.n_obs_steps, axis=1)  # (1, To, Do)
            gen = torch.Generator().manual_seed(int(seed))
            chunks = policy.predict_chunk(np.repeat(history, n, axis=0), generator=gen, **sampling)  # (n, Tp, 2)
            chunks = chunks.detach().cpu().numpy() if hasattr(chunks, "detach") else np.asarray(chunks)
            sides[name] = chunk_sides(chunks, state, policy.config.n_obs_steps)
        dp_sides += sides["dp"]
        reg_sides += sides["reg"]
        cw, ccw = sides["dp"].count("cw"), sides["dp"].count("ccw")
        minority.append(min(cw, ccw) / n_samples)
        both.append(min(cw, ccw) >= 0.1 * n_samples)
        print(f"  start {seed}: DP cw {cw} / ccw {ccw} / none {sides['dp'].count('none')} of {n_samples}; "
              f"regression {sides['reg'][0]}")
    dp_sides, reg_sides = np.asarray(dp_sides), np.asarray(reg_sides)
    expert = np.asarray(expert_sides)
    dp_with_expert = (dp_sides.reshape(len(starts), n_samples) == expert[:, None]).mean(1)  # (S,)
    base = f"{len(starts)} two-way starts (first ones among the evaluated seeds), reset observation; one training seed"
    return [
        {"name": "DP DDIM-10 chunks round neither side at a two-way start", "estimate": rate_estimate(dp_sides == "none"),
         "note": f"share of {n_samples} sampled chunks x {len(starts)} starts (pooled; samples from one start are "
                 f"not independent); cw {np.mean(dp_sides == 'cw'):.2f}, ccw {np.mean(dp_sides == 'ccw'):.2f}; {base}"},
        {"name": "DP DDIM-10 minority-side share of chunks at a two-way start", "estimate": mean_estimate(minority),
         "note": f"per start min(cw, ccw) / {n_samples}, mean over starts (0.5: an even split, 0: one way only); {base}"},
        {"name": "two-way starts where DP samples both ways (>= 10 % each)", "estimate": rate_estimate(np.asarray(both)),
         "note": f"{n_samples} DDIM-10 chunks per start; {base}"},
        {"name": "regression chunk round neither side at a two-way start", "estimate": rate_estimate(reg_sides == "none"),
         "note": f"one deterministic chunk per start; cw {np.mean(reg_sides == 'cw'):.2f}, "
                 f"ccw {np.mean(reg_sides == 'ccw'):.2f}; {base}"},
        {"name": "regression chunk goes the way the expert went at a two-way start",
         "estimate": rate_estimate(reg_sides == expert),
         "note": f"the expert's side is its seeded coin's; DP chunks going the expert's way: "
                 f"{np.mean(dp_with_expert):.2f} of samples (mean over starts); {base}"},
    ]
