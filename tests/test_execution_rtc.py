"""Real-time chunking: the weights' equation, the PiGDM gradient against torch's Jacobian, each policy's guided
head against its own unguided sampler, and the committed prefix on a real PushT rollout."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

import coursekit
from coursekit.data import MinMaxNormalizer
from coursekit.data.features import get_features
from coursekit.envs.pusht import PushTEnv
from coursekit.evaluate import rollout
from coursekit.execution.rtc import (RealTimeChunking, epsilon_guidance_scale, guidance_vjp, rtc_weights,
                                     sample_guided, velocity_guidance_weight)
from coursekit.nn.unet1d import UNet1DConfig
from coursekit.policies.diffusion import DenoisingHead, DiffusionPolicy, DiffusionPolicyConfig
from coursekit.policies.flow import EulerHead, FlowMatchingPolicy, FlowMatchingPolicyConfig

pytestmark = pytest.mark.usefixtures("one_torch_thread")
CKPT = Path(coursekit.__file__).parent / "checkpoints"
TINY = UNet1DConfig(down_dims=(16, 32), kernel_size=3, n_groups=4, diffusion_step_embed_dim=16)


def tiny_dp(steps: int = 3) -> DiffusionPolicy:
    torch.manual_seed(0)
    return DiffusionPolicy(DiffusionPolicyConfig(unet=TINY, num_inference_steps=steps),
                           {"obs": MinMaxNormalizer(np.array([0, 0, 0, 0, -1, -1.0]), np.array([512, 512, 512, 512, 1, 1.0])),
                            "action": MinMaxNormalizer(np.zeros(2), np.full(2, 512.0))})


@pytest.fixture(scope="module")
def dp():
    from coursekit.checkpoint import load_checkpoint

    return load_checkpoint(CKPT / "pusht_diffusion_state", device="cpu")


def test_weights_follow_the_rtc_equation():
    n, d, L = 12, 3, 9
    w = rtc_weights(n, d, L)
    for j in range(n):  # Black et al. 2025, eq. 5 with H - s = L
        if j < d:
            ref = 1.0
        elif j < L:
            c = (L - j) / (L - d + 1)
            ref = c * (math.exp(c) - 1) / (math.e - 1)
        else:
            ref = 0.0
        assert w[j] == pytest.approx(ref, abs=1e-12), f"W_{j}"
    assert np.all(np.diff(w[d:L]) < 0) and 0 < w[L - 1] < w[d] < 1
    np.testing.assert_array_equal(rtc_weights(n, d, L, "hard"), (np.arange(n) < d).astype(float))
    np.testing.assert_array_equal(rtc_weights(5, 4, 2), [1, 1, 1, 1, 0])  # overlap shorter than d: frozen only
    with pytest.raises(ValueError, match="schedule"):
        rtc_weights(4, 1, 2, "linear")


def test_guidance_vjp_is_jacobian_transpose_times_weighted_error():
    torch.manual_seed(1)
    lin = torch.nn.Linear(6, 6)

    def clean(x):  # a nonlinear "clean estimate" of x (1, 3, 2)
        out = torch.tanh(lin(x.reshape(1, 6))).reshape(1, 3, 2)
        return out, out * 2

    x, y = torch.randn(1, 3, 2), torch.randn(1, 3, 2)
    w = torch.tensor([1.0, 0.5, 0.0])
    x0, out, g = guidance_vjp(clean, x, y, w)
    jac = torch.autograd.functional.jacobian(lambda z: clean(z)[0], x).reshape(6, 6)  # d x0 / d x
    err = ((y - x0) * w.view(1, -1, 1)).reshape(6)
    torch.testing.assert_close(g.reshape(6), jac.T @ err)
    torch.testing.assert_close(out, 2 * x0)


@pytest.mark.parametrize("sampler,steps", [("ddim", 3), ("ddpm", 4)])
def test_unguided_diffusion_head_is_predict_chunk(sampler, steps):
    policy = tiny_dp()
    obs = np.random.default_rng(0).uniform(0, 500, size=(3, 2, 6)).astype(np.float32)
    ref = policy.predict_chunk(obs, sampler=sampler, num_inference_steps=steps, generator=torch.Generator().manual_seed(5))
    got = policy.predict_inpainted(obs, np.zeros((3, 4, 2)), np.zeros(4), sampler=sampler, num_inference_steps=steps,
                                   generator=torch.Generator().manual_seed(5))
    np.testing.assert_array_equal(got, ref)


class ToyFlow(torch.nn.Module):
    """A flow 'policy' head with random weights: v(x, t, cond) from the DP U-Net at time 100 t."""

    def __init__(self):
        super().__init__()
        torch.manual_seed(2)
        self.unet = tiny_dp().unet

    def velocity(self, x, t, cond):
        return self.unet(x, t * 100.0, cond)


def test_unguided_euler_head_is_plain_euler():
    flow, cond, x1 = ToyFlow(), torch.randn(2, 12), torch.randn(2, 16, 2)
    with torch.no_grad():
        x, n = x1.clone(), 4
        for i in range(n):  # x_{t+dt} = x_t + dt v(x_t, t), t = 1 - i/n, dt = -1/n
            x = x + (-1.0 / n) * flow.velocity(x, torch.full((2,), 1.0 - i / n), cond)
    got = sample_guided(EulerHead(flow.velocity, cond, n), x1, torch.zeros(2, 16, 2), torch.zeros(16))
    torch.testing.assert_close(got, x, rtol=0, atol=0)


def test_euler_guidance_weight_is_rtc_weight_in_pi0_time():
    for t in (0.9, 0.5, 0.2, 0.05):
        tau = 1.0 - t  # the paper's time: 0 noise, 1 data
        r2 = (1 - tau) ** 2 / (tau ** 2 + (1 - tau) ** 2)
        assert velocity_guidance_weight(t, 1e9) == pytest.approx((1 - tau) / (tau * r2))
        assert velocity_guidance_weight(t, 5.0) == pytest.approx(min(5.0, (1 - tau) / (tau * r2)))
    assert velocity_guidance_weight(1.0, 5.0) == 5.0


def test_ddim_guidance_is_pigdm_unclipped_and_rtc_clipped():
    for abar in (0.02, 0.5, 0.9, 0.999):
        # PiGDM: score += g / r^2 with r^2 = 1 - abar, and eps = -sqrt(1 - abar) score -> eps -= g / sqrt(1 - abar)
        assert epsilon_guidance_scale(abar, 1e9) == pytest.approx(1 / math.sqrt(1 - abar))
        tau = math.sqrt(abar) / (math.sqrt(abar) + math.sqrt(1 - abar))  # the rescaled flow time
        r2 = (1 - tau) ** 2 / (tau ** 2 + (1 - tau) ** 2)
        assert epsilon_guidance_scale(abar, 5.0) == pytest.approx(math.sqrt(abar) * min(5.0, (1 - tau) / (tau * r2)))


@pytest.mark.parametrize("head", ["diffusion", "flow"])
def test_guidance_pulls_the_overlap_toward_the_target(dp, head):
    obs = np.random.default_rng(3).uniform(100, 400, size=(4, 2, dp.config.obs_dim)).astype(np.float32)
    target = np.random.default_rng(4).uniform(100, 400, size=(4, 1, 2)).repeat(8, axis=1)  # (B, 8, Da)
    w = rtc_weights(8, 3, 8)
    # flow: the shipped DP's U-Net read as a (random-ish) velocity field: guidance must still pull
    policy = dp if head == "diffusion" else flow_from_dp(dp)
    free = policy.predict_inpainted(obs, target, np.zeros(8), generator=torch.Generator().manual_seed(0))
    guided = policy.predict_inpainted(obs, target, w, frozen=3, generator=torch.Generator().manual_seed(0))
    err = lambda c: float((w[None, :, None] * (c[:, 1:9] - target) ** 2).sum())  # noqa: E731
    assert err(guided) < 0.5 * err(free), (err(guided), err(free))
    np.testing.assert_array_equal(guided[:, 1:4], target[:, :3].astype(guided.dtype))  # frozen prefix, exactly


def flow_from_dp(dp) -> FlowMatchingPolicy:
    """A real flow policy (Euler-5) with a DP's inputs, normalisers and U-Net weights: v(x, t) = unet(x, 100 t)."""
    fields = {f: getattr(dp.config, f) for f in ("obs_type", "features", "obs_dim", "action_dim", "n_obs_steps",
                                                  "horizon", "n_action_steps", "unet", "vision")}
    flow = FlowMatchingPolicy(FlowMatchingPolicyConfig(**fields, num_inference_steps=5), dp.normalizers)
    flow.unet.load_state_dict(dp.unet.state_dict())
    return flow


def test_flow_policy_unguided_head_is_its_predict_chunk():
    torch.manual_seed(0)
    policy = FlowMatchingPolicy(FlowMatchingPolicyConfig(unet=TINY, num_inference_steps=3),
                                {"obs": MinMaxNormalizer(np.zeros(6), np.full(6, 512.0)),
                                 "action": MinMaxNormalizer(np.zeros(2), np.full(2, 512.0))})
    obs = np.random.default_rng(0).uniform(0, 500, size=(2, 2, 6)).astype(np.float32)
    ref = policy.predict_chunk(obs, generator=torch.Generator().manual_seed(9))
    got = policy.predict_inpainted(obs, np.zeros((2, 3, 2)), np.zeros(3), generator=torch.Generator().manual_seed(9))
    np.testing.assert_array_equal(got, ref)


def test_rtc_committed_prefix_equals_previous_chunk_on_pusht(dp):
    c, d = dp.config, 3
    gen = torch.Generator().manual_seed(0)
    features = get_features(c.features)
    pairs = []

    class Logged(RealTimeChunking):
        def _request(self):
            prev = self.current
            super()._request()
            if prev is not None:
                pairs.append((prev, self.pending))

    def factory(pc):
        return Logged(pc, c.n_obs_steps, c.n_action_steps, delay=d,
                      predict_inpainted=lambda h, y, w, **kw: dp.predict_inpainted(h, y, w, generator=gen, **kw))

    res = rollout(lambda h: dp.predict_chunk(h, generator=gen), lambda: PushTEnv(max_episode_steps=30),
                  lambda obs: features(np.stack(obs)), [100000, 100001], factory, max_steps=30, progress=False, record=True)
    assert len(pairs) >= 3
    for prev, new in pairs:
        committed = np.stack([prev.action_at(new.request + j) for j in range(d)], axis=1)  # (B, d, Da)
        np.testing.assert_array_equal(new.actions[:, :d], committed)
    assert np.isfinite(res.actions).all()


def test_replace_prefix_carries_the_target_along_its_own_noise():
    from coursekit.diffusion import DDIMSampler

    policy = tiny_dp()
    y, e = torch.randn(1, 16, 2), torch.randn(1, 16, 2)
    ddim = DenoisingHead(policy.unet, DDIMSampler(policy.schedule, 4), torch.zeros(1, 12))
    abar = policy.schedule.alphas_cumprod[ddim.timesteps[0] - ddim.sampler.step_ratio]
    torch.testing.assert_close(ddim.noised(y, e, 0), abar.sqrt() * y + (1 - abar).sqrt() * e)
    torch.testing.assert_close(ddim.noised(y, e, ddim.num_steps - 1), y)  # past the last step: clean
    euler = EulerHead(ToyFlow().velocity, torch.zeros(1, 12), 4)
    torch.testing.assert_close(euler.noised(y, e, 0), 0.75 * e + 0.25 * y)
    torch.testing.assert_close(euler.noised(y, e, 3), y)
    obs = np.random.default_rng(0).uniform(0, 500, size=(2, 2, 6)).astype(np.float32)
    target = np.random.default_rng(1).uniform(0, 500, size=(2, 5, 2))
    out = policy.predict_inpainted(obs, target, rtc_weights(5, 2, 5), frozen=2, prefix="replace",
                                   generator=torch.Generator().manual_seed(0))
    np.testing.assert_array_equal(out[:, 1:3], target[:, :2].astype(out.dtype))
    with pytest.raises(ValueError, match="prefix"):
        policy.predict_inpainted(obs, target, np.zeros(5), prefix="paste")


def test_unbatched_history_gives_one_chunk_with_the_frozen_prefix():
    policy = tiny_dp()
    obs = np.random.default_rng(2).uniform(0, 500, size=(2, 6)).astype(np.float32)  # (To, Do): no batch
    target = np.random.default_rng(3).uniform(0, 500, size=(1, 5, 2))
    kw = {"frozen": 2, "generator": torch.Generator().manual_seed(4)}
    one = policy.predict_inpainted(obs, target, rtc_weights(5, 2, 5), **kw)
    kw["generator"] = torch.Generator().manual_seed(4)
    batched = policy.predict_inpainted(obs[None], target, rtc_weights(5, 2, 5), **kw)
    assert one.shape == (16, 2)
    np.testing.assert_array_equal(one, batched[0])
    np.testing.assert_array_equal(one[1:3], target[0, :2].astype(one.dtype))


def test_the_guided_heads_run_each_policys_own_step():
    """With g = 0 a head's step IS its policy's sampler step: DDIM/DDPM's ``sampler.step``, flow's ``euler_step``."""
    from coursekit.diffusion import DDPMSampler
    from coursekit.flow.sampler import euler_step

    policy, cond = tiny_dp(), torch.randn(2, 12)
    x, gen = torch.randn(2, 16, 2), torch.Generator().manual_seed(0)
    head = policy.guided_head(cond, torch.Generator().manual_seed(1), sampler="ddpm", num_inference_steps=4)
    _, eps = head.clean(x, 1)
    want = DDPMSampler(policy.schedule, 4).step(eps, head.timesteps[1], x, generator=torch.Generator().manual_seed(1))
    torch.testing.assert_close(head.step(x, 1, eps, torch.zeros_like(x), 5.0), want, rtol=0, atol=0)
    flow = flow_from_dp(tiny_dp())
    euler = flow.guided_head(cond, gen)
    _, v = euler.clean(x, 2)
    t, t_next = euler.grid[2], euler.grid[3]  # 0.6, 0.4 of the Euler-5 grid
    torch.testing.assert_close(euler.step(x, 2, v, None, 5.0), euler_step(flow.velocity, x, t, t_next - t, cond),
                               rtol=0, atol=0)
    with pytest.raises(ValueError, match="Euler"):
        flow.guided_head(cond, gen, sampler="midpoint")
