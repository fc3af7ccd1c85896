"""Exercise 10.1 (flow_loss): training times and the flow-matching loss (pi0's convention).

References: the closed forms x_t = t e + (1 - t) a0, u = e - a0 written here, the Beta(1.5, 1)
CDF s^1.5, and torch's F.mse_loss.
"""

from __future__ import annotations

import math

import pytest
import torch
import torch.nn.functional as F

from coursekit.grading.compare import assert_close

EXERCISE = "flow_loss"


def _inputs(seed, shape=(4, 16, 2)):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(shape, generator=g) * 2 - 1, torch.randn(shape, generator=g), torch.rand(shape[0], generator=g)


def _scaled(t):
    return ((t.double() - 0.001) / 0.999).sort().values  # back to s in [0, 1)


def test_times_in_range_and_shape(student):
    for kind in ("beta", "uniform"):
        t = student.sample_flow_time(500, kind, generator=torch.Generator().manual_seed(0))
        assert torch.is_tensor(t) and t.shape == (500,), f"{kind}: expected a (500,) tensor, got {getattr(t, 'shape', t)}"
        assert t.dtype == torch.float32, f"{kind}: dtype {t.dtype}, expected float32"
        assert float(t.min()) >= 0.001 - 1e-7 and float(t.max()) < 1.0, f"{kind}: times must lie in [0.001, 1)"


def _ks(s, cdf):
    emp = torch.arange(1, len(s) + 1, dtype=torch.float64) / len(s)
    return float((cdf(s) - emp).abs().max())


def test_uniform_times_are_uniform(student):
    s = _scaled(student.sample_flow_time(20000, "uniform", generator=torch.Generator().manual_seed(1)))
    ks = _ks(s, lambda x: x)
    assert ks < 0.015, f"'uniform' times are not uniform on [0.001, 1): KS distance {ks:.3f}"


def test_beta_times_follow_beta_1_5_1(student):
    s = _scaled(student.sample_flow_time(20000, "beta", generator=torch.Generator().manual_seed(2)))
    ks = _ks(s, lambda x: x.clamp(min=0).pow(1.5))
    assert ks < 0.015, f"'beta' times do not follow Beta(1.5, 1) (CDF s^1.5) rescaled: KS distance {ks:.3f}"
    assert float(s.mean()) == pytest.approx(0.6, abs=0.01), "Beta(1.5, 1) has mean 0.6: more noisy (large) t"


def test_times_use_the_generator(student):
    a = student.sample_flow_time(16, "beta", generator=torch.Generator().manual_seed(3))
    b = student.sample_flow_time(16, "beta", generator=torch.Generator().manual_seed(3))
    c = student.sample_flow_time(16, "beta", generator=torch.Generator().manual_seed(4))
    assert torch.equal(a, b), "the same generator seed must give the same times"
    assert not torch.equal(a, c), "different generator seeds must give different times"


def test_model_sees_the_interpolated_chunk(student):
    a0, e, t = _inputs(5)
    cond = torch.randn(4, 3)
    seen = {}

    def model(x_t, tt, c):
        seen["x_t"], seen["t"], seen["cond"] = x_t, tt, c
        return torch.zeros_like(x_t)

    student.flow_matching_loss(model, a0, cond, t, e)
    assert "x_t" in seen, "flow_matching_loss must call velocity_model(x_t, t, cond)"
    for b in range(4):
        want = float(t[b]) * e[b] + (1 - float(t[b])) * a0[b]
        assert_close(seen["x_t"][b], want, rtol=1e-5, atol=1e-6,
                                   msg=lambda m: f"sample {b}: x_t must be t * noise + (1 - t) * a0: {m}")
    assert torch.equal(seen["t"], t), "the t given to velocity_model differs from the t passed in: pass it unchanged"
    assert seen["cond"] is not None and torch.equal(seen["cond"], cond), "pass cond to velocity_model unchanged"


def test_loss_matches_closed_form(student):
    a0, e, t = _inputs(6)
    loss = student.flow_matching_loss(lambda x, tt, c: 0.5 * x + tt[:, None, None], a0, None, t, e)
    total = 0.0
    for b in range(4):
        tb = float(t[b])
        x_t = tb * e[b] + (1 - tb) * a0[b]
        total += float(((0.5 * x_t + tb - (e[b] - a0[b])) ** 2).sum())
    assert torch.is_tensor(loss) and loss.ndim == 0, "the loss must be a 0-d tensor"
    assert float(loss) == pytest.approx(total / a0.numel(), rel=1e-5), \
        "loss = mean((v(x_t, t) - (noise - a0))^2) over all elements"


def test_loss_backpropagates(student, sandbox):
    a0, e, t = _inputs(7, shape=(3, 5))
    model = sandbox.new("coursekit.grading.worker:scale_model", 0.3)  # v = w * x_t, w a parameter (in the worker)
    loss, (grads,) = sandbox.grad(student.flow_matching_loss, model, a0, None, t, e, wrt=(model,))
    assert grads["w"] is not None and torch.isfinite(grads["w"]), \
        "no gradient reached the model's parameter: keep the loss a torch expression"
    w2 = torch.tensor(0.3, requires_grad=True)
    tb = t[:, None]
    F.mse_loss(w2 * (tb * e + (1 - tb) * a0), e - a0).backward()
    assert_close(grads["w"], w2.grad, rtol=1e-4, atol=1e-6,
                               msg=lambda m: f"d loss / d w (the model's parameter) differs: {m}")
    assert math.isfinite(float(loss.detach()))
