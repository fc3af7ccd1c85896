"""Exercise 4.1 (ddim_step): one DDIM update. References: the closed form, and diffusers'
DDIMScheduler through golden values (``golden_values()``, stored below by tests/exercises/golden.py)."""

from __future__ import annotations

import math

import pytest
import torch

from coursekit.diffusion.samplers import DDIMSampler
from coursekit.diffusion.schedules import NoiseSchedule
from coursekit.grading.compare import assert_close

EXERCISE = "ddim_step"

SCHEDULE = NoiseSchedule(num_train_timesteps=100)
SHAPE = (3, 16, 2)


def _eps_model(x, t, cond):
    return torch.tanh(x) * 0.8 + 0.3 * torch.sin(t.float()[:, None, None] / 7.0 + x)


def _ddim(x_t, eps, a_t, a_prev, eta=0.0, noise=None, clip=None, mistake=""):
    """The closed form (Song et al. 2021, eq. 12), or a named common mistake of it."""
    r = math.sqrt
    x0 = (x_t - r(1 - a_t) * eps) if mistake == "x0_hat not divided by sqrt(abar_t)" else (x_t - r(1 - a_t) * eps) / r(a_t)
    if clip is not None and mistake != "x0_hat not clipped":
        x0 = x0.clamp(-clip, clip)
    sigma = eta * r((1 - a_prev) / (1 - a_t) * (1 - a_t / a_prev)) if a_prev < 1 else 0.0
    keep = 1 - a_prev if mistake == "sigma^2 not taken out of the direction term" else 1 - a_prev - sigma ** 2
    scale = r(1 - a_t) if mistake == "direction term uses sqrt(1 - abar_t) instead of sqrt(1 - abar_prev)" else r(max(keep, 0.0))
    out = r(a_prev) * x0 + scale * eps
    if noise is not None and mistake != "the sigma * noise term is missing":
        out = out + sigma * noise
    return out


MISTAKES = ("x0_hat not divided by sqrt(abar_t)", "x0_hat not clipped", "direction term uses sqrt(1 - abar_t) instead "
            "of sqrt(1 - abar_prev)", "sigma^2 not taken out of the direction term", "the sigma * noise term is missing")


def _check(got, x_t, eps, a_t, a_prev, what, **kw):
    """Compare x_prev with the closed form; on a mismatch name the quantity that went wrong."""
    want = _ddim(x_t, eps, a_t, a_prev, **kw)
    assert tuple(got.shape) == tuple(want.shape), f"x_prev has shape {tuple(got.shape)}, expected {tuple(want.shape)} (same as x_t)"
    if torch.allclose(got, want, rtol=1e-5, atol=1e-5):
        return
    for mistake in MISTAKES:
        if torch.allclose(got, _ddim(x_t, eps, a_t, a_prev, mistake=mistake, **kw), rtol=1e-5, atol=1e-5):
            raise AssertionError(f"{what}: x_prev differs from the closed form; it matches the update with {mistake}")
    x0_only = torch.allclose(got, _ddim(x_t, eps, a_t, 1.0, clip=kw.get("clip")), rtol=1e-5, atol=1e-5)
    raise AssertionError(f"{what}: x_prev differs from the closed form (max error {float((got - want).abs().max()):.3g})"
                         + ("; it equals x0_hat: the sqrt(abar_prev) x0_hat + direction step is missing" if x0_only else ""))


REF_SHAPE = (2, 4, 2)
"""Shape of the chunks compared with diffusers step for step (small: their values are stored)."""
REF_RUNS = {"n=10 eta=0": (10, 0.0), "n=4 eta=0": (4, 0.0), "n=10 eta=1": (10, 1.0)}


def golden_values() -> dict[str, dict[str, list]]:
    """diffusers' DDIMScheduler from x_T = randn(REF_SHAPE, seed 3) with ``_eps_model`` and noise from
    seed 4: the timesteps and every step's prev_sample (flattened). Needs diffusers; the test reads the
    stored copy (GOLDEN), written by tests/exercises/golden.py."""
    import diffusers

    out = {}
    for name, (n, eta) in REF_RUNS.items():
        ref = diffusers.DDIMScheduler(num_train_timesteps=100, beta_schedule="squaredcos_cap_v2", clip_sample=True,
                                      prediction_type="epsilon", set_alpha_to_one=True, steps_offset=0)
        ref.set_timesteps(n)
        x, g, samples = torch.randn(REF_SHAPE, generator=torch.Generator().manual_seed(3)), torch.Generator().manual_seed(4), []
        for t in ref.timesteps.tolist():
            x = ref.step(_eps_model(x, torch.full((REF_SHAPE[0],), t, dtype=torch.long), None), t, x, eta=eta,
                         generator=g).prev_sample
            samples += x.flatten().tolist()
        out[name] = {"timesteps": ref.timesteps.tolist(), "prev_sample": samples}
    return out


def test_deterministic_step_closed_form(student):
    g = torch.Generator().manual_seed(0)
    x_t, eps = torch.randn(SHAPE, generator=g) * 0.5, torch.randn(SHAPE, generator=g)
    got = student.ddim_step(eps, x_t, 0.3, 0.7, eta=0.0, noise=None, clip_sample=False)
    _check(got, x_t, eps, 0.3, 0.7, "eta = 0, no clipping")


def test_clip_sample_clamps_x0_hat(student):
    g = torch.Generator().manual_seed(1)
    x_t, eps = torch.randn(SHAPE, generator=g) * 4, torch.randn(SHAPE, generator=g)
    got = student.ddim_step(eps, x_t, 0.5, 0.9, eta=0.0, noise=None, clip_sample=True, clip_sample_range=1.0)
    _check(got, x_t, eps, 0.5, 0.9, "clip_sample=True, range 1 (the direction term keeps the model's eps)", clip=1.0)


def test_stochastic_step_closed_form(student):
    g = torch.Generator().manual_seed(2)
    x_t, eps, noise = (torch.randn(SHAPE, generator=g) for _ in range(3))
    got = student.ddim_step(eps, x_t, 0.2, 0.6, eta=0.7, noise=noise, clip_sample=False)
    _check(got, x_t, eps, 0.2, 0.6, "eta = 0.7 with the given noise", eta=0.7, noise=noise)


@pytest.mark.parametrize("run", list(REF_RUNS))
def test_matches_diffusers_step_for_step(student, run):
    n, eta = REF_RUNS[run]
    ref = GOLDEN[run]
    ours = DDIMSampler(SCHEDULE, num_inference_steps=n, eta=eta, step_fn=student.ddim_step)
    assert ours.timesteps.tolist() == ref["timesteps"]
    x = torch.randn(REF_SHAPE, generator=torch.Generator().manual_seed(3))
    g_ours = torch.Generator().manual_seed(4)
    want_all = torch.tensor(ref["prev_sample"]).reshape(n, *REF_SHAPE)
    for t, want in zip(ref["timesteps"], want_all):
        tb = torch.full((REF_SHAPE[0],), t, dtype=torch.long)
        x = ours.step(_eps_model(x, tb, None), t, x, generator=g_ours)
        assert_close(x, want, rtol=1e-5, atol=1e-5,
                                   msg=lambda m: f"{n}-step DDIM (eta={eta}) differs from diffusers at t={t}: {m}")


def test_last_step_returns_clean_estimate(student):
    # Past the last step abar_prev = 1: x_prev is exactly the (clipped) x0 estimate.
    g = torch.Generator().manual_seed(5)
    x_t, eps = torch.randn(SHAPE, generator=g), torch.randn(SHAPE, generator=g)
    a_t = float(SCHEDULE.alphas_cumprod[0])
    got = student.ddim_step(eps, x_t, a_t, 1.0, eta=0.0, noise=None, clip_sample=True)
    assert torch.isfinite(got).all(), "x_prev is not finite with abar_prev = 1 (a division by 1 - abar_prev?)"
    _check(got, x_t, eps, a_t, 1.0, "abar_prev = 1 (the last step): x_prev must be the clipped x0_hat", clip=1.0)


# BEGIN GOLDEN: written by `python tests/exercises/golden.py` from golden_values(); do not edit
GOLDEN = {
    'n=10 eta=0': {
        'timesteps': [
            90, 80, 70, 60, 50, 40,
            30, 20, 10, 0,
        ],
        'prev_sample': [
            -0.162809238, 0.242881566, -0.894367695, -0.0321792215, 0.599104345, -0.351948142,
            1.26983428, -1.27360189, -0.140887275, -0.369984984, 0.131355003, -0.292759418,
            0.95319593, 0.0892400891, 0.484250546, 0.302795738, -0.0212032199, 0.386637419,
            -0.892026603, 0.112459332, 0.684314489, -0.223813981, 1.08667958, -1.23189473,
            0.0015193224, -0.243845701, 0.275850356, -0.159007818, 0.920628905, 0.233995631,
            0.596231699, 0.446424663, 0.034398824, 0.488266796, -0.962189257, 0.182891369,
            0.726929426, -0.19336313, 0.848345757, -0.974422336, 0.0596968979, -0.216174319,
            0.364383161, -0.119977809, 0.80239439, 0.317800611, 0.695099711, 0.555574954,
            -0.0253818631, 0.463713467, -0.911974311, 0.131484509, 0.734962463, -0.26323393,
            0.876863837, -0.915746629, 0.00119365752, -0.287013113, 0.327064842, -0.186747342,
            0.822870374, 0.276377708, 0.698181987, 0.539139152, -0.0745182335, 0.390214443,
            -0.915595829, 0.0713935941, 0.665467739, -0.29433912, 0.815417767, -0.919357061,
            -0.0499116033, -0.316387832, 0.256972253, -0.223582074, 0.757888615, 0.208359867,
            0.627264738, 0.465261757, -0.0356851891, 0.38404578, -0.841466904, 0.0957931429,
            0.639615297, -0.236416176, 0.782702446, -0.845330119, -0.0134560689, -0.256837338,
            0.262968063, -0.171283394, 0.727464318, 0.21907334, 0.603617966, 0.452903986,
            0.014179714, 0.412803113, -0.789137423, 0.139261246, 0.657551646, -0.178882986,
            0.796130598, -0.793185711, 0.0353809074, -0.198729292, 0.297786325, -0.115864404,
            0.742494285, 0.256162614, 0.622872412, 0.478434533, -0.000284228474, 0.385241002,
            -0.779572368, 0.119816236, 0.627634346, -0.185288101, 0.767097592, -0.78358686,
            0.0200425927, -0.204330444, 0.273030609, -0.124875464, 0.712939143, 0.232657328,
            0.592978418, 0.449741542, -0.0478750877, 0.297880352, -0.737999082, 0.0584261417,
            0.524207592, -0.210441262, 0.658145368, -0.741631687, -0.0299443491, -0.227147058,
            0.195721045, -0.157433152, 0.605811536, 0.159318775, 0.49134776, 0.357320577,
            -0.0465675034, 0.289943248, -0.720533669, 0.0568309054, 0.510929167, -0.204762831,
            0.642137408, -0.724103034, -0.0291261654, -0.221030638, 0.19043076, -0.153161213,
            0.5908283, 0.154996395, 0.478791267, 0.347902656,
        ],
    },
    'n=4 eta=0': {
        'timesteps': [
            75, 50, 25, 0,
        ],
        'prev_sample': [
            0.210666016, 0.674963534, -0.784809351, 0.381046832, 0.826680779, -0.0477325022,
            1.17618227, -1.1583395, 0.239877194, -0.0726943016, 0.57955265, 0.0339705944,
            0.934288919, 0.530113459, 0.783577025, 0.704423606, 0.0426402539, 0.468980134,
            -0.761649668, 0.187976688, 0.630762458, -0.161713868, 1.04429734, -1.12204194,
            0.0667978004, -0.18091172, 0.373139679, -0.0984567478, 0.75230217, 0.325262278,
            0.583638966, 0.499496758, 0.0894764364, 0.464725107, -0.658980548, 0.216086835,
            0.612395108, -0.0899643004, 1.00608158, -1.01112008, 0.110518575, -0.107049197,
            0.3789711, -0.0340097733, 0.725851953, 0.336551249, 0.568985879, 0.492289245,
            0.0870366767, 0.452767909, -0.642956674, 0.210260078, 0.597279966, -0.087511301,
            0.98466593, -0.989643753, 0.107508734, -0.104133204, 0.369026482, -0.0330805779,
            0.708599865, 0.327645123, 0.554756105, 0.479711801,
        ],
    },
    'n=10 eta=1': {
        'timesteps': [
            90, 80, 70, 60, 50, 40,
            30, 20, 10, 0,
        ],
        'prev_sample': [
            -0.962334394, 1.07874155, -0.708691716, 0.0114463866, 0.325305223, -0.473548055,
            -1.46188235, -0.216705322, -0.892439604, -0.41951403, 0.289187431, 0.354759187,
            0.466720641, -0.0272542275, -1.34439945, -1.75714004, 0.363512397, 0.317643464,
            -0.38586092, 0.136367455, 1.25321281, -0.304532051, -0.099185884, 0.614576578,
            -1.13997364, -0.22295554, -0.166045249, 0.306923002, 0.233266205, 0.810849488,
            -1.40947092, -1.56520689, 0.170120209, 1.13906991, 1.10015035, 0.397471189,
            0.656154454, 0.786042988, 0.160704106, 0.582088828, -1.26083302, -0.898471534,
            -0.635628939, 0.773872733, 0.807543278, 0.171163499, -2.11087179, -0.019938767,
            0.0408129804, 2.33910561, 0.693659365, 0.767430365, 1.0898397, 0.726349413,
            0.0655624121, 0.807004094, -1.35847259, -1.34052682, -0.819636822, -0.0982627869,
            1.41241336, -0.0414384753, -1.06910706, -0.777919054, -0.0485571735, 1.06665754,
            0.582199931, 0.779925883, 0.998300791, 0.380016327, -0.355595171, 0.727872074,
            -0.642084897, -0.41439569, -0.102704644, -0.270787954, 0.729773998, -0.632911146,
            -0.523619294, -0.618781209, 0.292324722, 1.76553869, 0.183043063, 0.662023246,
            0.944295883, 0.569095552, 0.355251551, 0.487847328, -0.0995111763, -0.117891788,
            -0.455315471, -0.305304557, 0.26504764, -0.79462415, -0.582544744, 0.0659478903,
            0.342920154, 0.742755413, 0.953293443, 0.615216911, 0.741135955, 0.152798086,
            0.2438346, 0.228703648, 0.0329918265, -0.250942409, -0.286609054, -0.0641085505,
            0.385314316, -0.273660988, -0.965277731, 0.118859328, 0.234777644, 0.700701773,
            0.762862563, 0.300006688, 0.715837896, 0.0288615525, -0.0310668498, 0.206267282,
            -0.0322752409, -0.0818701237, -0.430137277, -0.203031659, 0.148769513, -0.167309701,
            -0.879480302, -0.163032338, 0.172228575, 0.539917886, 0.650948286, 0.168135107,
            0.564408839, -0.042210184, -0.0443241894, 0.102340594, -0.0974801332, -0.10663414,
            -0.446458071, -0.185902029, 0.0671799332, -0.219229072, -0.812707007, -0.210381031,
            0.16756171, 0.526301324, 0.635077953, 0.163577333, 0.550274551, -0.0410571508,
            -0.0431134738, 0.0995520651, -0.0948232859, -0.103729375, -0.434919238, -0.180871755,
            0.0653462783, -0.213319898, -0.79399544, -0.20470418,
        ],
    },
}
# END GOLDEN
