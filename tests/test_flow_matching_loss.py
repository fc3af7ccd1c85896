"""The flow-matching objective against its closed form, and its time sampling against Beta(1.5, 1)."""

from __future__ import annotations

import math

import pytest
import torch
import torch.nn.functional as F

from coursekit.flow.loss import T_MIN, flow_loss, flow_matching_loss, sample_flow_time


def _inputs(seed=0, shape=(4, 16, 2)):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(shape, generator=g) * 2 - 1, torch.randn(shape, generator=g), torch.rand(shape[0], generator=g)


def test_loss_equals_its_closed_form_on_fixed_tensors():
    a0, e, t = _inputs()
    w = torch.tensor(0.7)
    loss = flow_matching_loss(lambda x, tt, c: w * x + c * tt[:, None, None], a0, 0.3, t, e)
    total = 0.0
    for b in range(4):  # element by element, no broadcasting tricks
        tb = float(t[b])
        x_t = tb * e[b] + (1 - tb) * a0[b]
        total += float(((0.7 * x_t + 0.3 * tb - (e[b] - a0[b])) ** 2).sum())
    assert loss.ndim == 0
    assert float(loss) == pytest.approx(total / a0.numel(), rel=1e-5)


def test_loss_is_zero_for_the_true_velocity_of_one_pair_and_endpoints():
    a0, e, t = _inputs(1)
    assert float(flow_matching_loss(lambda x, tt, c: e - a0, a0, None, t, e)) == 0.0
    # at t = 1 the model sees pure noise, at t = 0 the data itself
    seen = []
    flow_matching_loss(lambda x, tt, c: seen.append(x) or x, a0, None, torch.ones(4), e)
    flow_matching_loss(lambda x, tt, c: seen.append(x) or x, a0, None, torch.zeros(4), e)
    torch.testing.assert_close(seen[0], e)
    torch.testing.assert_close(seen[1], a0)


def test_loss_gradient_matches_autograd_of_the_reference():
    a0, e, t = _inputs(2, shape=(3, 5))
    w1 = torch.tensor(0.4, requires_grad=True)
    w2 = torch.tensor(0.4, requires_grad=True)
    flow_matching_loss(lambda x, tt, c: w1 * x, a0, None, t, e).backward()
    tb = t[:, None]
    F.mse_loss(w2 * (tb * e + (1 - tb) * a0), e - a0).backward()
    torch.testing.assert_close(w1.grad, w2.grad)


def test_beta_times_follow_the_rescaled_beta_cdf():
    t = sample_flow_time(20000, "beta", generator=torch.Generator().manual_seed(0))
    assert t.shape == (20000,) and t.dtype == torch.float32
    assert float(t.min()) >= T_MIN and float(t.max()) < 1.0
    s = ((t - T_MIN) / (1 - T_MIN)).double().sort().values
    cdf = s.pow(1.5)  # Beta(1.5, 1) CDF
    emp = torch.arange(1, 20001, dtype=torch.float64) / 20000
    ks = float((cdf - emp).abs().max())
    assert ks < 1.36 / math.sqrt(20000) * 1.2, ks  # Kolmogorov-Smirnov, ~5 % level (with slack)
    assert float(s.mean()) == pytest.approx(0.6, abs=0.01)  # Beta(1.5, 1) mean = 1.5 / 2.5


def test_uniform_times_and_determinism():
    t = sample_flow_time(20000, "uniform", generator=torch.Generator().manual_seed(0))
    assert float(t.mean()) == pytest.approx(T_MIN + (1 - T_MIN) / 2, abs=0.01)
    a = sample_flow_time(8, "beta", generator=torch.Generator().manual_seed(3))
    b = sample_flow_time(8, "beta", generator=torch.Generator().manual_seed(3))
    assert torch.equal(a, b)
    with pytest.raises(ValueError, match="'gamma'"):
        sample_flow_time(8, "gamma")


def test_flow_loss_draws_t_and_noise_from_the_generator():
    a0, _, _ = _inputs(4)
    got = {}

    def spy(model, x0, cond, t, noise):
        got["t"], got["noise"] = t, noise
        return flow_matching_loss(model, x0, cond, t, noise)

    g = torch.Generator().manual_seed(9)
    loss = flow_loss(lambda x, t, c: torch.zeros_like(x), a0, None, "beta", generator=g, loss_fn=spy)
    g2 = torch.Generator().manual_seed(9)
    torch.testing.assert_close(got["t"], sample_flow_time(4, "beta", generator=g2))
    torch.testing.assert_close(got["noise"], torch.randn(a0.shape, generator=g2))
    torch.testing.assert_close(loss, F.mse_loss(torch.zeros_like(a0), got["noise"] - a0))
    with pytest.raises(ValueError, match="NaN"):
        flow_loss(lambda x, t, c: x, a0 * float("nan"), None)
