"""Diffusion Policy (Chi et al., RSS 2023): a chunk of actions sampled by denoising, given observations.

Training (Sec. 3.1, eq. 5): normalise a window's To observations and Tp actions to [-1, 1], noise
the action chunk to a random step t, and train the conditional U-Net to predict the noise::

    loss = E_{t, eps} || eps - eps_theta(sqrt(abar_t) a_0 + sqrt(1 - abar_t) eps, t, o) ||^2

Inference (eq. 4): start from a_T ~ N(0, I) (B, Tp, Da) and denoise with DDPM (T = 100 steps, as in
the paper's simulation results) or DDIM (10 steps by default: a CPU needs it), then unnormalise.
``num_inference_steps=None`` means the sampler's own default (DDIM: 10, DDPM: T); a number is
used as given by whichever sampler runs, so no setting silently depends on another.
``predict_chunk`` returns all Tp actions; which of them are executed is the executor's business
(``coursekit.execution.RecedingHorizon``: pred[To-1 : To-1+Ta]).

Departures from the reference code, on purpose: no observation inpainting / local conditioning
(the paper's best state results use global FiLM conditioning, as here); DDIM is the default
sampler for speed (``sampler="ddpm"`` reproduces the paper's evaluation setting).

DDIM walks the reference code's "leading" timesteps (90, 80, ..., 0 for 10 steps);
``ddim_timestep_spacing="trailing"`` walks diffusers' 99, 89, ..., 9 instead, which starts where
pure noise really is the network's training input (Lin et al. 2024). On a 20-minute CPU model
(clean demonstrations, (x, y, sin, cos) state) it was no better, measured: 0.828 vs 0.782
(trailing vs leading) on 100 validation seeds from 200000, but 0.723 vs 0.788 on the 50
protocol seeds from 100000 — differences of this size are evaluation noise (score stderr ~0.05
at 50 episodes), so the paper's choice stays the default. (Measured with ``coursekit eval CKPT
--ddim-spacing {leading,trailing} [--episodes 100 --seed-start 200000]``.)

Real-time chunking (chapter 11) steers the same sampler step by step: :class:`DenoisingHead`
(``guided_head``) runs the policy's own sampler step on a guided epsilon, the PiGDM guidance of
:mod:`coursekit.execution.rtc`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import torch

from coursekit.diffusion.loss import diffusion_loss, epsilon_loss, q_sample
from coursekit.diffusion.samplers import TIMESTEP_SPACINGS, DDIMSampler, DDPMSampler, EpsModel, predict_x0
from coursekit.diffusion.schedules import NoiseSchedule
from coursekit.execution.rtc import epsilon_guidance_scale, guided_update
from coursekit.policies.base import Normalizer
from coursekit.policies.unet_chunk import IterativeUNetPolicy, UNetChunkConfig

SAMPLERS = ("ddim", "ddpm")
DEFAULT_DDIM_STEPS = 10
"""DDIM's own step count when none is given (the paper's code evaluates DDIM with 10 steps on a CPU budget)."""


@dataclass
class DiffusionPolicyConfig(UNetChunkConfig):
    """Diffusion Policy: the shared inputs/U-Net settings plus the noise schedule and sampler."""

    num_train_timesteps: int = 100
    """T: diffusion steps of the forward process."""
    beta_schedule: str = "squaredcos_cap_v2"
    """Noise schedule: 'squaredcos_cap_v2' (cosine, paper) or 'linear'."""
    clip_sample: bool = True
    """Clip the predicted clean chunk to [-1, 1] at every sampler step (needs min-max normalisation)."""
    sampler: str = "ddim"
    """Default sampler for predict_chunk: 'ddim' (fast) or 'ddpm' (the paper's simulation setting)."""
    num_inference_steps: int | None = None
    """Denoising steps of the default sampler; None: that sampler's own default (DDIM 10, DDPM T)."""
    ddim_eta: float = 0.0
    """DDIM stochasticity: 0 = deterministic given a_T (Song et al. 2021, eq. 16)."""
    ddim_timestep_spacing: str = "leading"
    """DDIM timesteps: 'leading' (90, 80, ..., 0 for 10 steps; the paper's code) or 'trailing' (99, 89, ..., 9)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not isinstance(self.num_train_timesteps, int) or self.num_train_timesteps < 2:
            raise ValueError(f"num_train_timesteps must be an int >= 2, got {self.num_train_timesteps!r}")
        if self.beta_schedule not in ("squaredcos_cap_v2", "linear"):
            raise ValueError(f"beta_schedule must be 'squaredcos_cap_v2' or 'linear', got {self.beta_schedule!r}")
        if self.sampler not in SAMPLERS:
            raise ValueError(f"sampler must be one of {SAMPLERS}, got {self.sampler!r}")
        n = self.num_inference_steps
        if n is not None and (not isinstance(n, int) or isinstance(n, bool) or not 1 <= n <= self.num_train_timesteps):
            raise ValueError(f"num_inference_steps must be None or an int in [1, T={self.num_train_timesteps}], "
                             f"got {self.num_inference_steps!r}")
        if self.ddim_timestep_spacing not in TIMESTEP_SPACINGS:
            raise ValueError(f"ddim_timestep_spacing must be one of {TIMESTEP_SPACINGS}, got {self.ddim_timestep_spacing!r}")
        if not 0.0 <= float(self.ddim_eta) <= 1.0:
            raise ValueError(f"ddim_eta must be in [0, 1], got {self.ddim_eta!r}")


class DenoisingHead:
    """A diffusion sampler (DDIM or DDPM) one step at a time, guided on epsilon (real-time chunking).

    ``clean``: the network's eps and x0_hat = ``predict_x0`` (unclipped: the clamp has no gradient);
    ``step``: the sampler's own step on eps' = ``guided_update(eps, g, epsilon_guidance_scale(abar_t,
    beta))`` = eps - scale * g; ``noised``: ``q_sample`` to the noise level the step's output x_prev
    is at (clean past the last step).
    """

    def __init__(self, eps_model: EpsModel, sampler: DDIMSampler | DDPMSampler, cond: torch.Tensor,
                 generator: torch.Generator | None = None) -> None:
        self.eps_model, self.sampler, self.cond, self.generator = eps_model, sampler, cond, generator
        self.timesteps = [int(t) for t in sampler.timesteps.tolist()]
        self.num_steps = len(self.timesteps)

    def clean(self, x: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Step k: x0_hat (B, Tp, Da) from the iterate x (B, Tp, Da), and the network's eps."""
        t = self.timesteps[k]
        eps = self.eps_model(x, torch.full((x.shape[0],), t, dtype=torch.long, device=x.device), self.cond)
        return predict_x0(eps, x, self.sampler.schedule.alphas_cumprod[t]), eps

    def guidance_scale(self, k: int, max_guidance: float) -> float:
        """Step k: the factor of g taken off eps, sqrt(abar_t) min(beta, 1 / sqrt(abar_t (1 - abar_t)))."""
        return epsilon_guidance_scale(float(self.sampler.schedule.alphas_cumprod[self.timesteps[k]]), max_guidance)

    def step(self, x: torch.Tensor, k: int, eps: torch.Tensor, g: torch.Tensor | None, max_guidance: float) -> torch.Tensor:
        """Step k: x_prev from x with the guided eps (g None: the plain sampler step)."""
        t = self.timesteps[k]
        if g is not None:
            eps = guided_update(eps, g, self.guidance_scale(k, max_guidance))
        return self.sampler.step(eps, t, x, generator=self.generator)

    def noised(self, clean: torch.Tensor, noise: torch.Tensor, k: int) -> torch.Tensor:
        """sqrt(abar_prev) clean + sqrt(1 - abar_prev) noise, (B, Tp, Da): the level x_prev of step k is at."""
        prev = self.sampler.previous_timestep(self.timesteps[k])
        if prev < 0:  # past the last step: abar = 1, the clean chunk itself
            return clean
        t = torch.full((clean.shape[0],), prev, dtype=torch.long, device=clean.device)  # (B,)
        return q_sample(clean, t, noise, self.sampler.schedule.alphas_cumprod)


class DiffusionPolicy(IterativeUNetPolicy):
    """Epsilon-prediction Diffusion Policy over action chunks (B, Tp, Da). See module docstring."""

    policy_type = "diffusion"
    config_class = DiffusionPolicyConfig
    config: DiffusionPolicyConfig
    eval_overrides = ("n_action_steps", "ddim_timestep_spacing", "ddim_eta")
    sampling_options = ("sampler", "num_inference_steps", "return_trajectory")

    def __init__(self, config: DiffusionPolicyConfig, normalizers: Mapping[str, Normalizer] | None = None):
        super().__init__(config, normalizers)
        self.schedule = NoiseSchedule(num_train_timesteps=config.num_train_timesteps,
                                      beta_schedule=config.beta_schedule)

    def compute_loss(self, batch: Mapping[str, Any], loss_fn: Callable[..., torch.Tensor] = epsilon_loss,
                     generator: torch.Generator | None = None) -> dict[str, torch.Tensor]:
        """Raw batch {obs keys: (B, To, ...), "action": (B, Tp, Da)} -> {"loss": scalar}.

        ``loss_fn`` is the epsilon loss (a student's ``epsilon_loss`` plugs in here);
        t and eps come from ``generator`` (None: torch's global generator).
        """
        cond, action_n = self._batch_parts(batch)  # (B, cond_dim), (B, Tp, Da)
        loss = diffusion_loss(self.unet, action_n, cond, self.schedule, generator=generator, loss_fn=loss_fn)
        return {"loss": loss}

    def make_sampler(self, sampler: str | None = None, num_inference_steps: int | None = None) -> DDIMSampler | DDPMSampler:
        """A sampler over this policy's schedule.

        ``sampler`` None: the config's; ``num_inference_steps`` None: the config's when the config's
        sampler is used, else (and when the config's is None too) the sampler's own default
        (DDIM 10, DDPM T). An explicit 0 or out-of-range count is refused by the sampler, never replaced.
        """
        c = self.config
        kind = c.sampler if sampler is None else sampler
        if num_inference_steps is None and kind == c.sampler:
            num_inference_steps = c.num_inference_steps
        if kind == "ddim":
            steps = DEFAULT_DDIM_STEPS if num_inference_steps is None else num_inference_steps
            return DDIMSampler(self.schedule, steps, eta=c.ddim_eta,
                               clip_sample=c.clip_sample, timestep_spacing=c.ddim_timestep_spacing)
        if kind == "ddpm":
            return DDPMSampler(self.schedule, num_inference_steps, clip_sample=c.clip_sample)
        raise ValueError(f"sampler must be one of {SAMPLERS}, got {kind!r}")

    def guided_head(self, cond: torch.Tensor, generator: torch.Generator | None = None, sampler: str | None = None,
                    num_inference_steps: int | None = None) -> DenoisingHead:
        """The sampler ``predict_chunk`` would run (same options), one step at a time for RTC's guidance."""
        return DenoisingHead(self.unet, self.make_sampler(sampler, num_inference_steps), cond, generator)

    def describe_sampling(self, **sampling: Any) -> dict[str, Any]:
        """Which sampler and how many steps ``predict_chunk(..., **sampling)`` runs (for evaluation reports)."""
        self.check_sampling(sampling)
        kind, steps = sampling.get("sampler"), sampling.get("num_inference_steps")
        used = self.make_sampler(kind, steps)
        return {"sampler": kind or self.config.sampler, "num_inference_steps": len(used.timesteps),
                "first_timestep": int(used.timesteps[0])}

    @torch.no_grad()
    def predict_chunk(self, obs_history: Any, *, generator: torch.Generator | None = None, sampler: str | None = None,
                      num_inference_steps: int | None = None, return_trajectory: bool = False) -> Any:
        """Raw history (B, To, Do) (or dict for images; or unbatched (To, Do)) -> raw chunk (B, Tp, Da).

        Numpy in, numpy out; tensors in, tensors out. ``sampler``/``num_inference_steps`` override
        the config; a_T and any sampler noise come from ``generator`` (None: global generator).
        With ``return_trajectory`` also returns the denoising path (n+1, B, Tp, Da) in raw units.
        """
        sampler_obj = self.make_sampler(sampler, num_inference_steps)

        def draw(cond: torch.Tensor, shape: tuple[int, int, int]) -> Any:
            x_T = self.initial_noise(shape, generator, cond.device)  # (B, Tp, Da)
            return sampler_obj.sample(self.unet, shape, cond=cond, generator=generator, device=cond.device, x_T=x_T,
                                      return_trajectory=return_trajectory)

        return self._sample_chunk(obs_history, draw, return_trajectory)
