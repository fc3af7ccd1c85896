"""Guided (inpainted) chunk sampling for real-time chunking, on the diffusion and flow heads.

:mod:`coursekit.execution.rtc` holds what RTC shares between samplers (weights, the PiGDM
vector-Jacobian product g, the loop). Here are the two samplers seen one step at a time:

DDIM on epsilon (Diffusion Policy)::

    x0_hat = (x_t - sqrt(1 - abar_t) eps) / sqrt(abar_t)              (unclipped: the clamp has no gradient)
    eps'   = eps - sqrt(abar_t) * min(beta, 1 / sqrt(abar_t (1 - abar_t))) * g
    x_prev = the policy's own sampler step with eps'                    (DDIM, or DDPM)

Unclipped this is PiGDM exactly: score = -eps / sqrt(1 - abar_t), and PiGDM adds g / r_t^2 to
the score with r_t^2 = 1 - abar_t, i.e. eps' = eps - g / sqrt(1 - abar_t). The clip is RTC's, on
the same quantity RTC clips: rescaled, x_t is a flow iterate at tau = sqrt(abar) / (sqrt(abar) +
sqrt(1 - abar)), where RTC's weight (1 - tau) / (tau r^2) equals 1 / sqrt(abar (1 - abar)).
(Clipping 1 / r_t^2 itself instead would all but switch guidance off in the last, low-noise
steps, where 1 / r_t^2 is in the hundreds and the chunk takes its final shape.)

Euler on velocity (flow matching, pi0's convention: x_t = t e + (1 - t) a0, t = 1 noise, v = e - a0)::

    x0_hat = x_t - t v
    v'     = v - min(beta, ((1 - t)^2 + t^2) / ((1 - t) t)) * g
    x_next = x_t + dt v',   dt = -1/N

which is RTC's Algorithm 1 written in this convention (their tau = 1 - t runs toward the data,
their velocity is -v, and (1 - tau) / (tau r^2) with r^2 = (1 - tau)^2 / (tau^2 + (1 - tau)^2)
becomes the weight above; at t = 1 it is infinite and the clip takes over).

With all-zero weights both heads reproduce the policy's own ``predict_chunk`` exactly (same noise
from the same generator, same steps): tests/test_execution_rtc.py checks it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from coursekit.execution.rtc import MAX_GUIDANCE, sample_guided
from coursekit.policies.flow import check_steps


PREFIX_MODES = ("guide", "replace")


class DDIMHead:
    """A diffusion policy's sampler (DDIM or DDPM) with PiGDM guidance on epsilon."""

    def __init__(self, eps_model: Callable[..., torch.Tensor], sampler: Any, cond: torch.Tensor,
                 generator: torch.Generator | None = None) -> None:
        self.eps_model, self.sampler, self.cond, self.generator = eps_model, sampler, cond, generator
        self.timesteps = [int(t) for t in sampler.timesteps.tolist()]
        self.num_steps = len(self.timesteps)

    def clean(self, x: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
        t = self.timesteps[k]
        abar_t = self.sampler.schedule.alphas_cumprod[t].to(x)
        eps = self.eps_model(x, torch.full((x.shape[0],), t, dtype=torch.long, device=x.device), self.cond)
        return (x - (1.0 - abar_t).sqrt() * eps) / abar_t.sqrt(), eps

    @staticmethod
    def guidance_scale(abar: float, max_guidance: float) -> float:
        """sqrt(abar) * min(beta, 1 / sqrt(abar (1 - abar))): the factor of g subtracted from eps."""
        if abar >= 1.0:
            return 0.0
        return abar ** 0.5 * min(float(max_guidance), 1.0 / (abar * (1.0 - abar)) ** 0.5)

    def step(self, x: torch.Tensor, k: int, eps: torch.Tensor, g: torch.Tensor | None, max_guidance: float) -> torch.Tensor:
        t = self.timesteps[k]
        if g is not None:
            eps = eps - self.guidance_scale(float(self.sampler.schedule.alphas_cumprod[t]), max_guidance) * g
        return self.sampler.step(eps, t, x, generator=self.generator)

    def noised(self, clean: torch.Tensor, noise: torch.Tensor, k: int) -> torch.Tensor:
        """sqrt(abar_prev) clean + sqrt(1 - abar_prev) noise: the level x_prev of step k is at."""
        prev = self.sampler.previous_timestep(self.timesteps[k])
        abar = self.sampler.schedule.alphas_cumprod[prev].to(clean) if prev >= 0 else torch.ones((), dtype=clean.dtype)
        return abar.sqrt() * clean + (1.0 - abar).sqrt() * noise


class EulerHead:
    """A flow policy's Euler integration (t = 1 noise -> t = 0 data) with RTC's guidance on velocity."""

    def __init__(self, velocity: Callable[..., torch.Tensor], cond: torch.Tensor, steps: int) -> None:
        if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
            raise ValueError(f"steps must be a positive int, got {steps!r}")
        self.velocity, self.cond, self.num_steps = velocity, cond, steps
        self.grid = [1.0 - i / steps for i in range(steps + 1)]  # t_i, noise to data

    def clean(self, x: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
        t = self.grid[k]
        v = self.velocity(x, torch.full((x.shape[0],), t, dtype=x.dtype, device=x.device), self.cond)
        return x - t * v, v

    @staticmethod
    def guidance_weight(t: float, max_guidance: float) -> float:
        """min(beta, ((1 - t)^2 + t^2) / ((1 - t) t)); infinite (so beta) at t = 1."""
        if t >= 1.0 or t <= 0.0:
            return float(max_guidance)
        return min(float(max_guidance), ((1.0 - t) ** 2 + t ** 2) / ((1.0 - t) * t))

    def step(self, x: torch.Tensor, k: int, v: torch.Tensor, g: torch.Tensor | None, max_guidance: float) -> torch.Tensor:
        t, t_next = self.grid[k], self.grid[k + 1]
        if g is not None:
            v = v - self.guidance_weight(t, max_guidance) * g
        return x + (t_next - t) * v

    def noised(self, clean: torch.Tensor, noise: torch.Tensor, k: int) -> torch.Tensor:
        """t_next noise + (1 - t_next) clean: the straight path's point after step k."""
        t_next = self.grid[k + 1]
        return t_next * noise + (1.0 - t_next) * clean


def predict_inpainted(policy: Any, obs_history: Any, target: Any, weights: Any, *, frozen: int = 0,
                      generator: torch.Generator | None = None, max_guidance: float = MAX_GUIDANCE,
                      offset: int | None = None, prefix: str = "guide", **sampling: Any) -> Any:
    """A chunk (B, Tp, Da) from ``policy`` whose steps ``offset + j`` are guided toward ``target[:, j]``.

    Args:
        policy: a DiffusionPolicy (any sampler) or a FlowMatchingPolicy (Euler).
        obs_history: raw history (B, To, ...) as for ``predict_chunk``.
        target: Y, raw actions (B, n, Da) for chunk indices offset .. offset + n - 1.
        weights: W (n,) in [0, 1] (:func:`coursekit.execution.rtc.rtc_weights`).
        frozen: the first ``frozen`` target actions are copied verbatim into the result.
        generator: draws the starting noise (and DDPM's step noise), as ``predict_chunk`` does.
        max_guidance: beta, the clip of the guidance weight (RTC: 5).
        offset: chunk index of target[:, 0] (default To - 1: the action for "now").
        prefix: "guide" (RTC: the frozen prefix is held by guidance with W = 1) or "replace"
            (also overwrite the iterate's frozen prefix at every step with the committed actions
            at that step's noise level: Diffusion Policy's inpainting; a departure from RTC).
        sampling: the policy's sampling options (diffusion: sampler, num_inference_steps;
            flow: num_inference_steps).
    Returns raw actions, numpy if the history was numpy.
    """
    kind = getattr(policy, "policy_type", "")
    if prefix not in PREFIX_MODES:
        raise ValueError(f"prefix must be one of {PREFIX_MODES}, got {prefix!r}")
    unknown = sorted(set(sampling) - {"sampler", "num_inference_steps"})
    if unknown:
        raise ValueError(f"predict_inpainted takes the sampling options sampler and num_inference_steps, got {unknown}")
    if kind not in ("diffusion", "flow"):
        raise ValueError(f"real-time chunking needs an iterative sampler (a 'diffusion' or 'flow' policy); "
                         f"got policy_type {kind!r}")
    policy._require_normalizers()
    c = policy.config
    offset = c.n_obs_steps - 1 if offset is None else int(offset)
    w = np.asarray(weights, dtype=np.float64)
    y = np.asarray(target.detach().cpu() if hasattr(target, "detach") else target, dtype=np.float64)
    if y.ndim != 3 or w.shape != (y.shape[1],) or offset + y.shape[1] > c.horizon or y.shape[2] != c.action_dim:
        raise ValueError(f"target must be (B, n, Da={c.action_dim}) with weights (n,) and offset + n <= Tp={c.horizon}; "
                         f"got target {y.shape}, weights {w.shape}, offset {offset}")
    if not (np.all(np.isfinite(w)) and np.all(w >= 0)) or not 0 <= frozen <= y.shape[1]:
        raise ValueError(f"weights must be finite and >= 0 and 0 <= frozen <= n={y.shape[1]}; got {w}, frozen={frozen}")
    obs, unbatched = policy._obs_dict(obs_history)
    was_training = policy.training
    policy.eval()
    try:
        cond = policy.encode_obs(obs).detach()  # (B, cond_dim)
        b, dev = cond.shape[0], cond.device
        if y.shape[0] != b:
            raise ValueError(f"target has batch {y.shape[0]}, the observations {b}")
        full_y = torch.zeros(b, c.horizon, c.action_dim, device=dev)  # (B, Tp, Da), normalised
        full_y[:, offset:offset + y.shape[1]] = policy.normalizers["action"].normalize(
            torch.as_tensor(y, dtype=torch.float32, device=dev))
        full_w = torch.zeros(c.horizon, device=dev)  # (Tp,)
        full_w[offset:offset + len(w)] = torch.as_tensor(w, dtype=torch.float32, device=dev)
        shape = (b, c.horizon, c.action_dim)
        gen_device = generator.device if generator is not None else dev
        x = torch.randn(shape, generator=generator, device=gen_device).to(dev)  # (B, Tp, Da), as predict_chunk draws it
        if kind == "diffusion":
            sampler = policy.make_sampler(sampling.get("sampler"), sampling.get("num_inference_steps"))
            head: Any = DDIMHead(policy.unet, sampler, cond, generator)
        else:
            method = sampling.get("sampler") or c.integration_method
            if method != "euler":
                raise ValueError(f"real-time chunking on a flow policy integrates with Euler, got sampler {method!r}")
            n = sampling.get("num_inference_steps")
            head = EulerHead(policy.velocity, cond, c.num_inference_steps if n is None else check_steps(n))
        replace = None
        if prefix == "replace" and frozen:
            replace = torch.zeros(c.horizon, dtype=torch.bool, device=dev)
            replace[offset:offset + frozen] = True
        chunk_n = sample_guided(head, x, full_y, full_w, max_guidance, replace=replace)
        if kind == "flow":
            chunk_n = chunk_n.clamp(-1.0, 1.0)  # as FlowMatchingPolicy.predict_chunk
    finally:
        policy.train(was_training)
    chunk = policy._finish(chunk_n, obs_history, unbatched)
    if frozen:
        sl = (Ellipsis, slice(offset, offset + frozen), slice(None)) if not unbatched else (slice(offset, offset + frozen),)
        src = y[..., :frozen, :] if not unbatched else y[0, :frozen]
        if isinstance(chunk, np.ndarray):
            chunk[sl] = src
        else:
            chunk[sl] = chunk.new_tensor(src)
    return chunk
