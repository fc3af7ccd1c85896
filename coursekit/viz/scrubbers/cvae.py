"""Chapter 7's scrubber: beta and the latent z of ACT's CVAE, the decoded chunk redrawn in place.

ACT (Zhao et al. 2023, Sec. IV-B) trains its chunk decoder as a conditional VAE; the weight
beta of the KL term decides how much the decoder relies on the latent z. :func:`cvae_scrubber`
takes one trained toy CVAE per beta and lets the student move z along the most-used latent
dimension and the observation o.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from coursekit.viz.scrubbers.figure import FigureScrubber

__all__ = ["cvae_scrubber"]


def cvae_scrubber(models: dict[float, Any], posterior: Callable[[Any], tuple[Any, Any]],
                  modes: Sequence[np.ndarray] = (), z_range: float = 3.0):
    """Chapter 7: pick beta (one trained toy CVAE per value) and move the latent z along the
    model's most-used dimension (the others stay 0, the prior's mean) and the observation o;
    the decoded chunk is redrawn in place, over the prior's spread.

    Args:
        models: beta -> trained ``ACTPolicy`` with Do = Da = 1.
        posterior: policy -> (mu, logvar) (n, d) of held-out demonstrations (picks the dimension).
        modes: optional (K,) curves drawn dotted for reference (the true modes at o = 0).
    """
    import ipywidgets as widgets
    import torch

    from coursekit.nn.kl import gaussian_kl_per_dim

    used = {}
    for beta, policy in models.items():
        mu, logvar = posterior(policy)
        used[beta] = int(torch.argmax(gaussian_kl_per_dim(mu, logvar)))

    def draw(fig: Figure, beta: float, z: float, o: float) -> None:
        policy = models[beta]
        d = policy.config.latent_dim
        ax = fig.add_subplot()
        with torch.no_grad():
            o_n = policy.normalizers["obs"].normalize(torch.full((9, 1), float(o)))
            zs = torch.zeros(9, d)
            zs[:, used[beta]] = torch.linspace(-2, 2, 9)
            spread = policy.normalizers["action"].unnormalize(policy.decode(o_n, zs))[..., 0].numpy()  # (9, K)
            one = torch.zeros(1, d)
            one[0, used[beta]] = float(z)
            chunk = policy.normalizers["action"].unnormalize(policy.decode(o_n[:1], one))[0, :, 0].numpy()  # (K,)
        j = np.arange(1, chunk.shape[0] + 1)
        for s in spread:
            ax.plot(j, s, color="0.8", lw=1)
        for curve in modes:
            ax.plot(j, float(o) + np.asarray(curve), ":", color="tab:red", lw=1)
        ax.plot(j, chunk, "k-o", lw=2, ms=3, label=f"decoded at z[{used[beta]}] = {z:+.2f}")
        ax.set(xlabel="step j", ylabel="action", ylim=(-2.1, 2.1),
               title=f"beta = {beta}: grey = z[{used[beta]}] from -2 to 2 (prior's range), others 0")
        ax.legend(fontsize=8, loc="lower left")

    betas = sorted(models)
    controls = {
        "beta": widgets.SelectionSlider(options=betas, value=betas[len(betas) // 2], description="beta"),
        "z": widgets.FloatSlider(value=0.0, min=-z_range, max=z_range, step=0.1, description="z"),
        "o": widgets.FloatSlider(value=0.0, min=-1.0, max=1.0, step=0.1, description="o"),
    }
    return FigureScrubber(draw, controls, figsize=(6.5, 3.6))
