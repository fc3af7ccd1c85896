"""Flow matching on a 1-D two-mode mixture: the exact marginal field and a field learned in seconds."""

from __future__ import annotations

import pytest
import torch

from coursekit.flow.sampler import integrate
from coursekit.flow.toy import Mixture1D, mode_fractions, train_toy_flow

MIX = Mixture1D(weights=(0.3, 0.7), means=(-2.0, 2.0), stds=(0.25, 0.25))


def _noise(n=4000, seed=1):
    return torch.randn(n, 1, generator=torch.Generator().manual_seed(seed))


def test_exact_field_matches_monte_carlo_conditional_expectation():
    # v*(x, t) = E[e - a0 | x_t = x]: estimate it from pairs whose x_t falls in a narrow bin
    g = torch.Generator().manual_seed(0)
    a0, e = MIX.sample(400000, generator=g), torch.randn(400000, 1, generator=g)
    # points where x_t has density (the field is steep in the gap between modes at small t)
    for t, x in ((0.3, -1.4), (0.3, 1.4), (0.6, -0.8), (0.6, 0.0), (0.6, 0.8), (0.9, -1.0), (0.9, 0.2), (0.9, 1.0)):
        x_t = t * e + (1 - t) * a0
        near = (x_t - x).abs() < 0.02
        assert int(near.sum()) > 1000
        mc = float((e - a0)[near].mean())
        exact = float(MIX.velocity(torch.tensor([[x]]), torch.tensor([t])))
        assert exact == pytest.approx(mc, abs=0.08), (t, x, exact, mc)


def test_one_step_with_the_exact_field_lands_on_the_mean():
    x0 = integrate(MIX.velocity, _noise(), steps=1)
    torch.testing.assert_close(x0, torch.full_like(x0, MIX.mean), atol=1e-5, rtol=0)
    frac = mode_fractions(integrate(MIX.velocity, _noise(), steps=64), [0.0])
    assert frac == pytest.approx(list(MIX.weights), abs=0.02)


@pytest.mark.slow
def test_learned_flow_reproduces_mode_weights_at_16_steps():
    torch.manual_seed(0)
    with torch.no_grad():
        model = train_toy_flow(MIX, steps=1500, seed=0)  # ~4 s on one CPU thread
        x0 = integrate(model, _noise(), steps=16)
        one = integrate(model, _noise(), steps=1)
    frac = mode_fractions(x0, [0.0])
    # tolerance 0.05 per mode (sampling error of 4000 draws is ~0.007; the rest is training/Euler)
    assert frac == pytest.approx(list(MIX.weights), abs=0.05), frac
    # the learned one-step sampler collapses onto the mean between the modes, as the exact one does
    assert float(one.mean()) == pytest.approx(MIX.mean, abs=0.15)
    assert float(one.std()) < 0.3
