"""Chapter 11 reproduces itself: guided (RTC) chunks and delayed-execution episodes against recorded values.

``tests/golden/latency.npz`` was recorded ONCE from the shipped checkpoints with fixed seeds (by
this module run as a script, ``python -m tests.test_latency_golden RECORD_PATH``), before the
chapter-11 code was regrouped; every later change of that code must give the same numbers bit for
bit: the guided samples of the diffusion (DDIM, DDPM) and flow (Euler) heads, and the actions,
scores, chunk switches and smoothness of seeded episodes under every delay strategy.

Bit-identity holds for the torch build and CPU the values were recorded on (the fingerprint
stored with them: torch build, vector extension and CPU model; an AMD EPYC with the same AVX512
path as the recording Intel Xeon rounds differently). Elsewhere a network's sums round
differently, so there the guided chunks are compared to 1e-3 px, and the 32-step episodes (too
short for contact to amplify rounding: on the EPYC their actions stay within 2.5e-4 px and their
states within 7.6e-4 of the recording) to 1e-2 px, with the chunk switches and calls exact.
"""

from __future__ import annotations

import platform
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

import coursekit

pytestmark = [pytest.mark.usefixtures("one_torch_thread"), pytest.mark.slow]  # ~2 min on 2 busy cores
CKPT = Path(coursekit.__file__).parent / "checkpoints"
GOLDEN = Path(__file__).parent / "golden" / "latency.npz"
HEADS = {"dp": "pusht_diffusion_state", "flow": "pusht_flow_state", "act": "act_pusht"}
SEEDS = [100000, 100001]
STEPS = 32

# name -> (head, sampling options, frozen d, weights (n, d, L, schedule), guided-sampler options)
CHUNKS = {
    "dp_ddim_guide": ("dp", {}, 3, (15, 3, 9, "exp"), {}),
    "dp_ddim_free": ("dp", {}, 0, None, {}),
    "dp_ddim_hard_clip20": ("dp", {}, 2, (15, 2, 15, "hard"), {"max_guidance": 20.0}),
    "dp_ddim_replace": ("dp", {}, 3, (15, 3, 9, "exp"), {"prefix": "replace"}),
    "dp_ddpm4_guide": ("dp", {"sampler": "ddpm", "num_inference_steps": 4}, 2, (15, 2, 10, "exp"), {}),
    "flow_euler_guide": ("flow", {}, 3, (15, 3, 9, "exp"), {}),
    "flow_euler4_replace": ("flow", {"num_inference_steps": 4}, 2, (15, 2, 12, "exp"), {"prefix": "replace"}),
}
# name -> (head, strategy, d, sampling options, RTC options)
EPISODES = {
    "dp_sync_d2": ("dp", "sync", 2, {}, {}),
    "dp_async_d2": ("dp", "async", 2, {}, {}),
    "dp_ensemble_d2": ("dp", "ensemble", 2, {}, {}),
    "dp_rtc_d0": ("dp", "rtc", 0, {}, {}),
    "dp_rtc_d2": ("dp", "rtc", 2, {}, {}),
    "dp_rtc_d3_replace_hard": ("dp", "rtc", 3, {}, {"prefix": "replace", "schedule": "hard", "max_guidance": 10.0}),
    "dp_ddpm4_rtc_d2": ("dp", "rtc", 2, {"sampler": "ddpm", "num_inference_steps": 4}, {}),
    "flow_rtc_d2": ("flow", "rtc", 2, {}, {}),
    "flow_async_d1": ("flow", "async", 1, {}, {}),
    "act_ensemble_d2": ("act", "ensemble", 2, {}, {}),
    "act_sync_d1": ("act", "sync", 1, {}, {}),
}
SMOOTHNESS_KEYS = ("max_step", "switch_jump", "other_step", "max_jerk")


def fingerprint() -> str:
    """Where bit-identity is promised: the torch build, the CPU's vector extensions and its model."""
    from benchmarks.shipped_golden import fingerprint as machine

    return (f"torch {torch.__version__} {platform.machine()} {torch.backends.cpu.get_cpu_capability()} "
            f"{machine()['cpu']}")


def load_heads() -> dict:
    from coursekit.checkpoint import load_checkpoint

    return {k: load_checkpoint(CKPT / v, device="cpu") for k, v in HEADS.items()}


def guided_chunk(policies: dict, name: str) -> np.ndarray:
    """One guided chunk (2, Tp, Da) of case ``name``: a previous chunk shifted 20 px as the target."""
    from coursekit.execution.rtc import rtc_weights

    head, sampling, frozen, weights, options = CHUNKS[name]
    policy = policies[head]
    c = policy.config
    obs = np.random.default_rng(7).uniform(100, 400, size=(2, c.n_obs_steps, c.obs_dim)).astype(np.float32)
    prev = policy.predict_chunk(obs, generator=torch.Generator().manual_seed(1), **sampling)  # (2, Tp, Da)
    n = c.horizon - (c.n_obs_steps - 1)
    target = prev[:, c.n_obs_steps - 1:] + np.array([20.0, -10.0])  # (2, n, Da)
    w = np.zeros(n) if weights is None else rtc_weights(*weights)
    return policy.predict_inpainted(obs, target, w, frozen=frozen, generator=torch.Generator().manual_seed(2),
                                    **options, **sampling)


def delayed_episodes(policies: dict, name: str) -> dict[str, np.ndarray]:
    """Seeded PushT episodes of case ``name``: what the executed actions, scores and switches were."""
    from coursekit.evaluate import evaluate, make_adapter, smoothness
    from coursekit.execution.rtc import STRATEGIES

    head, strategy, d, sampling, options = EPISODES[name]
    policy = policies[head]
    r = evaluate(policy, make_adapter("pusht", policy), SEEDS, seed=3, sampling=sampling, max_steps=STEPS,
                 record=True, executor_cls=STRATEGIES[strategy], executor_options={"delay": d, **options},
                 progress=False)
    smooth = smoothness(r.actions, r.info["switches"])
    return {"actions": r.actions, "states": r.states, "max_reward": r.max_reward, "success": r.success,
            "length": r.length, "switches": np.asarray(r.info["switches"]), "chunk_calls": np.asarray(r.chunk_calls),
            "smoothness": np.array([smooth[k] for k in SMOOTHNESS_KEYS])}


@pytest.fixture(scope="module")
def golden():
    if not GOLDEN.is_file():
        pytest.fail(f"{GOLDEN} is missing: it is committed with this test")
    with np.load(GOLDEN) as data:
        return {k: data[k] for k in data.files}


@pytest.fixture(scope="module")
def policies():
    return load_heads()


def exact(golden) -> bool:
    return str(golden["fingerprint"]) == fingerprint()


@pytest.mark.parametrize("name", sorted(CHUNKS))
def test_guided_chunk_is_as_recorded(policies, golden, name):
    got, want = guided_chunk(policies, name), golden[f"chunk/{name}"]
    if exact(golden):
        np.testing.assert_array_equal(got, want)
    else:
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-3)


@pytest.mark.parametrize("name", sorted(EPISODES))
def test_delayed_episodes_are_as_recorded(policies, golden, name):
    got = delayed_episodes(policies, name)
    if not exact(golden):  # another CPU: rounding, not amplified in 32 steps; the schedule itself is exact
        for key, value in got.items():
            want = golden[f"episode/{name}/{key}"]
            if key in ("switches", "chunk_calls", "success", "length"):
                np.testing.assert_array_equal(value, want, err_msg=f"{name}: {key}")
            else:  # px (actions, states, smoothness), radians (block angle) and coverage (max_reward)
                np.testing.assert_allclose(value, want, rtol=0, atol=1e-2, err_msg=f"{name}: {key}")
        return
    for key, value in got.items():
        want = golden[f"episode/{name}/{key}"]
        if key in ("smoothness", "max_reward"):
            # ulps only: the jerk is one third-difference formula whose rounding order may differ, and the
            # coverage (max_reward) now comes from element-wise T corners (coursekit.envs.pusht_geometry)
            # instead of a BLAS product; actions, states and success stay bit-exact.
            np.testing.assert_allclose(value, want, rtol=1e-12, atol=0, err_msg=f"{name}: {key}")
        else:
            np.testing.assert_array_equal(value, want, err_msg=f"{name}: {key}")


def record(path: Path) -> None:
    """Write the golden file (refuses to overwrite one)."""
    if path.exists():
        raise SystemExit(f"{path} exists: not overwriting a recorded golden file")
    torch.set_num_threads(1)
    policies = load_heads()
    out: dict[str, np.ndarray] = {"fingerprint": np.array(fingerprint())}
    for name in CHUNKS:
        out[f"chunk/{name}"] = guided_chunk(policies, name)
    for name in EPISODES:
        for key, value in delayed_episodes(policies, name).items():
            out[f"episode/{name}/{key}"] = value
        print(name, out[f"episode/{name}/max_reward"], flush=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **out)
    print(f"wrote {path} ({path.stat().st_size} bytes)")


if __name__ == "__main__":
    record(Path(sys.argv[1]))
