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

Real-time chunking (chapter 11) steers the same integration step by step: :class:`EulerHead`
(``guided_head``) runs the Euler step of :mod:`coursekit.flow.sampler` on a guided velocity, RTC's
Algorithm 1 (:mod:`coursekit.execution.rtc`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Callable

import torch

from coursekit.execution.rtc import guided_update, velocity_guidance_weight
from coursekit.flow.loss import TIME_SAMPLINGS, flow_loss, flow_matching_loss
from coursekit.flow.sampler import METHODS, VelocityModel, euler_step, integrate, time_grid
from coursekit.policies.unet_chunk import IterativeUNetPolicy, UNetChunkConfig

MAX_INFERENCE_STEPS = 1000
"""Most integration steps a flow policy takes: 10 suffice (pi0), Euler's error is O(1/N), so beyond 1000
steps only the time grows (an unbounded N is a hang, not a finer answer)."""


@dataclass
class FlowMatchingPolicyConfig(UNetChunkConfig):
    """Flow matching: the shared inputs/U-Net settings plus time sampling and the ODE sampler."""

    time_sampling: str = "beta"
    """Training times: 'beta' (pi0: Beta(1.5, 1) in [0.001, 1), more noisy times) or 'uniform'."""
    num_inference_steps: int = 10
    """N, integration steps from noise to data at inference (pi0 uses 10), at most MAX_INFERENCE_STEPS."""
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
        check_steps(self.num_inference_steps)
        if not float(self.time_scale) > 0:
            raise ValueError(f"time_scale must be > 0, got {self.time_scale!r}")


def check_steps(n: Any) -> int:
    """``n`` if it is an int in [1, MAX_INFERENCE_STEPS], else ValueError showing it."""
    if not isinstance(n, int) or isinstance(n, bool) or not 1 <= n <= MAX_INFERENCE_STEPS:
        raise ValueError(f"num_inference_steps must be an int in [1, {MAX_INFERENCE_STEPS}] for a flow policy, got {n!r}")
    return n


class EulerHead:
    """Euler integration (t = 1 noise -> t = 0 data) one step at a time, guided on velocity (real-time chunking).

    ``clean``: the network's v and x0_hat = x_t - t v; ``step``: ``euler_step`` with the guided
    velocity v' = ``guided_update(v, g, velocity_guidance_weight(t, beta))`` = v - weight * g over
    the grid ``time_grid(steps)``;
    ``noised``: the straight path's point t_next e + (1 - t_next) a0 after the step.
    """

    def __init__(self, velocity: VelocityModel, cond: torch.Tensor, steps: int) -> None:
        self.velocity, self.cond = velocity, cond
        self.grid = time_grid(steps)  # t_i = 1 - i / N, noise to data
        self.num_steps = steps

    def clean(self, x: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Step k: x0_hat (B, Tp, Da) from the iterate x (B, Tp, Da), and the network's v."""
        t = self.grid[k]
        v = self.velocity(x, torch.full((x.shape[0],), t, dtype=x.dtype, device=x.device), self.cond)
        return x - t * v, v

    def guidance_scale(self, k: int, max_guidance: float) -> float:
        """Step k: RTC's weight of g at t_k, min(beta, ((1 - t)^2 + t^2) / ((1 - t) t))."""
        return velocity_guidance_weight(self.grid[k], max_guidance)

    def step(self, x: torch.Tensor, k: int, v: torch.Tensor, g: torch.Tensor | None, max_guidance: float) -> torch.Tensor:
        """Step k: x at t_{k+1} from x at t_k with the guided velocity (g None: the plain Euler step)."""
        t, t_next = self.grid[k], self.grid[k + 1]
        if g is not None:
            v = guided_update(v, g, self.guidance_scale(k, max_guidance))
        return euler_step(lambda *_: v, x, t, t_next - t, self.cond)  # v is already evaluated at (x, t)

    def noised(self, clean: torch.Tensor, noise: torch.Tensor, k: int) -> torch.Tensor:
        """t_next noise + (1 - t_next) clean, (B, Tp, Da): the straight path's point after step k."""
        t_next = self.grid[k + 1]
        return t_next * noise + (1.0 - t_next) * clean


class FlowMatchingPolicy(IterativeUNetPolicy):
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

    def finish_sample(self, chunk_n: torch.Tensor) -> torch.Tensor:
        """Clamp the integrated chunk (B, Tp, Da) to [-1, 1], the range of the normalised data."""
        return chunk_n.clamp(-1.0, 1.0)

    def guided_head(self, cond: torch.Tensor, generator: torch.Generator | None = None, sampler: str | None = None,
                    num_inference_steps: int | None = None) -> EulerHead:
        """The Euler integration ``predict_chunk`` would run, one step at a time for RTC's guidance."""
        method = sampler or self.config.integration_method
        if method != "euler":
            raise ValueError(f"real-time chunking on a flow policy integrates with Euler, got sampler {method!r}")
        n = num_inference_steps
        return EulerHead(self.velocity, cond, self.config.num_inference_steps if n is None else check_steps(n))

    def describe_sampling(self, **sampling: Any) -> dict[str, Any]:
        """Which integrator, how many steps and U-Net calls ``predict_chunk(..., **sampling)`` runs (for reports)."""
        self.check_sampling(sampling)
        method = sampling.get("sampler") or self.config.integration_method
        if method not in METHODS:
            raise ValueError(f"sampler must be one of {METHODS} for a flow policy, got {method!r}")
        steps = self._steps(sampling.get("num_inference_steps"))
        return {"sampler": method, "num_inference_steps": steps,
                "network_calls": steps * (2 if method == "midpoint" else 1)}

    def _steps(self, n: int | None) -> int:
        """N: ``num_inference_steps`` as given (checked) or, when None, the config's."""
        return self.config.num_inference_steps if n is None else check_steps(n)

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
        n = self._steps(num_inference_steps)
        method = sampler or self.config.integration_method
        if method not in METHODS:
            raise ValueError(f"sampler must be one of {METHODS} for a flow policy, got {method!r}")

        def draw(cond: torch.Tensor, shape: tuple[int, int, int]) -> Any:
            x1 = self.initial_noise(shape, generator, cond.device)  # (B, Tp, Da) at t = 1
            out = integrate(self.velocity, x1, cond, steps=n, method=method, step_fn=step_fn,
                            return_trajectory=return_trajectory)
            chunk_n, traj_n = out if return_trajectory else (out, None)
            chunk_n = self.finish_sample(chunk_n)  # (B, Tp, Da)
            return (chunk_n, traj_n) if return_trajectory else chunk_n

        return self._sample_chunk(obs_history, draw, return_trajectory)
