"""Flow-matching policy: Diffusion Policy's chunk, U-Net and data, with a velocity head (§10.3).

Everything but the objective and the sampler is shared with
:class:`~coursekit.policies.diffusion.DiffusionPolicy` (same observations, min-max
normalisation, To/Tp/Ta, FiLM U-Net, trainer), so a comparison isolates the generative head.

Training (pi0's convention, Black et al. 2024; :mod:`coursekit.flow.loss`)::

    x_t = t e + (1 - t) a0,   loss = || v_theta(x_t, t, o) - (e - a0) ||^2,   t ~ Beta(1.5, 1) in [0.001, 1)

Inference (:mod:`coursekit.flow.sampler`): x_1 = e ~ N(0, I) (B, Tp, Da), then N Euler steps of
dt = -1/N down to t = 0 (N = 10 as in pi0; ``--steps`` at evaluation), then unnormalise.

The U-Net's step embedding was built for integer diffusion steps 0..T-1; it gets
``time_scale * t`` (100 t by default) so flow time in [0, 1] spans the same range of the
sinusoidal embedding as DP's 100 steps. Departures, on purpose: the final chunk is clamped to
[-1, 1], the range of the normalised data (DP clips its clean estimate at every step; pi0 does not
clip); no clipping inside the integration, which would bend the ODE.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Callable

import torch

from coursekit.flow.loss import TIME_SAMPLINGS, flow_loss, flow_matching_loss
from coursekit.flow.sampler import METHODS, integrate
from coursekit.policies.unet_chunk import UNetChunkConfig, UNetChunkPolicy


@dataclass
class FlowMatchingPolicyConfig(UNetChunkConfig):
    """Flow matching: the shared inputs/U-Net settings plus time sampling and the ODE sampler."""

    time_sampling: str = "beta"
    """Training times: 'beta' (pi0: Beta(1.5, 1) in [0.001, 1), more noisy times) or 'uniform'."""
    num_inference_steps: int = 10
    """N, integration steps from noise to data at inference (pi0 uses 10)."""
    integration_method: str = "euler"
    """'euler' (one U-Net call per step) or 'midpoint' (second order, two calls per step)."""
    time_scale: float = 100.0
    """The U-Net's sinusoidal step embedding gets time_scale * t (DP's steps span 0..99)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.time_sampling not in TIME_SAMPLINGS:
            raise ValueError(f"time_sampling must be one of {TIME_SAMPLINGS}, got {self.time_sampling!r}")
        if self.integration_method not in METHODS:
            raise ValueError(f"integration_method must be one of {METHODS}, got {self.integration_method!r}")
        if not isinstance(self.num_inference_steps, int) or isinstance(self.num_inference_steps, bool) \
                or self.num_inference_steps < 1:
            raise ValueError(f"num_inference_steps must be a positive int, got {self.num_inference_steps!r}")
        if not float(self.time_scale) > 0:
            raise ValueError(f"time_scale must be > 0, got {self.time_scale!r}")


class FlowMatchingPolicy(UNetChunkPolicy):
    """Velocity-prediction chunk policy on the Diffusion Policy U-Net. See module docstring."""

    policy_type = "flow"
    config_class = FlowMatchingPolicyConfig
    config: FlowMatchingPolicyConfig
    sampling_options = ("sampler", "num_inference_steps", "return_trajectory", "step_fn")

    def velocity(self, x_t: torch.Tensor, t: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """v_theta: chunk x_t (B, Tp, Da), times t (B,) in [0, 1], condition (B, cond_dim) -> (B, Tp, Da)."""
        return self.unet(x_t, t * self.config.time_scale, cond)

    def compute_loss(self, batch: Mapping[str, Any], loss_fn: Callable[..., torch.Tensor] = flow_matching_loss,
                     generator: torch.Generator | None = None) -> dict[str, torch.Tensor]:
        """Raw batch {obs keys: (B, To, ...), "action": (B, Tp, Da)} -> {"loss": scalar}.

        ``loss_fn`` is the flow-matching loss (a student's ``flow_matching_loss`` plugs in here);
        t and e come from ``generator`` (None: torch's global generator).
        """
        cond, action_n = self._batch_parts(batch)  # (B, cond_dim), (B, Tp, Da)
        loss = flow_loss(self.velocity, action_n, cond, self.config.time_sampling, generator=generator, loss_fn=loss_fn)
        return {"loss": loss}

    def describe_sampling(self, **sampling: Any) -> dict[str, Any]:
        """Which integrator, how many steps and U-Net calls ``predict_chunk(..., **sampling)`` runs (for reports)."""
        self.check_sampling(sampling)
        method = sampling.get("sampler") or self.config.integration_method
        if method not in METHODS:
            raise ValueError(f"sampler must be one of {METHODS} for a flow policy, got {method!r}")
        steps = sampling.get("num_inference_steps")
        steps = self.config.num_inference_steps if steps is None else steps
        return {"sampler": method, "num_inference_steps": steps,
                "network_calls": steps * (2 if method == "midpoint" else 1)}

    @torch.no_grad()
    def predict_chunk(self, obs_history: Any, *, generator: torch.Generator | None = None, sampler: str | None = None,
                      num_inference_steps: int | None = None, return_trajectory: bool = False,
                      step_fn: Callable[..., torch.Tensor] | None = None) -> Any:
        """Raw history (B, To, Do) (or dict for images; or unbatched (To, Do)) -> raw chunk (B, Tp, Da).

        Numpy in, numpy out; tensors in, tensors out. ``sampler`` ('euler'/'midpoint') and
        ``num_inference_steps`` override the config; x_1 comes from ``generator``
        (None: global generator). ``step_fn`` replaces the integration step (e.g. a student's
        ``euler_step``). With ``return_trajectory`` also returns the path (N+1, B, Tp, Da) in raw units.
        """
        n = self.config.num_inference_steps if num_inference_steps is None else num_inference_steps
        method = sampler or self.config.integration_method
        if method not in METHODS:
            raise ValueError(f"sampler must be one of {METHODS} for a flow policy, got {method!r}")

        def draw(cond: torch.Tensor, shape: tuple[int, int, int]) -> Any:
            gen_device = generator.device if generator is not None else cond.device
            x1 = torch.randn(shape, generator=generator, device=gen_device).to(cond.device)  # (B, Tp, Da) at t = 1
            out = integrate(self.velocity, x1, cond, steps=n, method=method, step_fn=step_fn,
                            return_trajectory=return_trajectory)
            chunk_n, traj_n = out if return_trajectory else (out, None)
            chunk_n = chunk_n.clamp(-1.0, 1.0)  # (B, Tp, Da): the range of the normalised data
            return (chunk_n, traj_n) if return_trajectory else chunk_n

        return self._sample_chunk(obs_history, draw, return_trajectory)
