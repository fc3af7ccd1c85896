"""Reverse-process samplers: DDPM (ancestral, Ho et al. 2020) and DDIM (Song et al. 2021).

Both work on ANY epsilon model ``eps_model(x_t (B, ...), t (B,) long, cond) -> eps_hat (B, ...)``
and agree step for step with ``diffusers``' DDPMScheduler / DDIMScheduler (epsilon prediction,
``clip_sample=True``, DDPM variance "fixed_small", DDIM ``set_alpha_to_one=True``, "leading"
timestep spacing), which is how Diffusion Policy runs them. ``tests/test_diffusion_samplers.py``
checks that to 1e-5.

Each sampler walks ``n`` timesteps ``t_i = i * (T // n)`` downwards (99, 98, ..., 0 for DDPM-100;
90, 80, ..., 0 for DDIM-10); one step maps ``x_t`` to ``x_prev`` at ``prev = t - T // n`` and, past
the last step, to abar = 1 (the clean sample). DDIM also takes diffusers' "trailing" spacing
(Lin et al. 2024, "Common diffusion noise schedules and sample steps are flawed", Table 2):
``t_i = round(T - i T / n) - 1``, i.e. 99, 89, ..., 9 for DDIM-10, so the walk starts at the
last trained timestep, where x_T ~ N(0, I) really is the model's input distribution; "leading"
starts at t = 90 and treats pure noise as x_90, which still holds a trace of the signal.

``ddim_step`` is exercise "ddim_step"; ``DDIMSampler(step_fn=...)`` takes a student's version.
"""

from __future__ import annotations

from typing import Any, Callable

import torch

from coursekit.diffusion.schedules import NoiseSchedule

Scalar = float | torch.Tensor
TIMESTEP_SPACINGS = ("leading", "trailing")
EpsModel = Callable[[torch.Tensor, torch.Tensor, Any], torch.Tensor]


def predict_x0(eps: torch.Tensor, x_t: torch.Tensor, abar_t: Scalar) -> torch.Tensor:
    """Invert the forward process for the clean sample (Ho et al. 2020, eq. 15).

        x0_hat = (x_t - sqrt(1 - abar_t) * eps) / sqrt(abar_t)
    """
    abar_t = torch.as_tensor(abar_t, dtype=x_t.dtype, device=x_t.device)
    return (x_t - (1.0 - abar_t).sqrt() * eps) / abar_t.sqrt()


def ddim_step(eps: torch.Tensor, x_t: torch.Tensor, abar_t: Scalar, abar_prev: Scalar,
              eta: float = 0.0, noise: torch.Tensor | None = None, clip_sample: bool = True,
              clip_sample_range: float = 1.0) -> torch.Tensor:
    """One DDIM update from x_t to x_prev (Song et al. 2021, eq. 12 and 16).

        x0_hat = (x_t - sqrt(1 - abar_t) eps) / sqrt(abar_t), clamped to [-r, r] if clip_sample
        sigma  = eta * sqrt((1 - abar_prev) / (1 - abar_t)) * sqrt(1 - abar_t / abar_prev)
        x_prev = sqrt(abar_prev) x0_hat + sqrt(1 - abar_prev - sigma^2) eps + sigma * noise

    The direction term uses the model's eps, NOT an eps re-derived from the clipped x0_hat
    (diffusers' default ``use_clipped_model_output=False``). eta = 0 is deterministic; eta = 1
    recovers DDPM's posterior variance.

    Args:
        eps: predicted noise, (B, ...).
        x_t: current sample, (B, ...).
        abar_t: alpha-bar at the current timestep (converted here to a 0-d tensor like x_t).
        abar_prev: alpha-bar at the previous timestep, 1.0 past the last step (also a 0-d tensor).
        eta: stochasticity, >= 0.
        noise: standard normal, like x_t; required when eta > 0, ignored when eta == 0.
        clip_sample: clamp x0_hat to [-clip_sample_range, clip_sample_range].
        clip_sample_range: r above.

    Returns:
        x_prev, same shape as x_t.
    """
    if eta > 0 and (noise is None or noise.shape != x_t.shape):
        raise ValueError(f"ddim_step with eta={eta} > 0 needs `noise` shaped like x_t {tuple(x_t.shape)}")
    abar_t = torch.as_tensor(abar_t, dtype=x_t.dtype, device=x_t.device)
    abar_prev = torch.as_tensor(abar_prev, dtype=x_t.dtype, device=x_t.device)
    # BEGIN SOLUTION
    x0_hat = (x_t - (1.0 - abar_t).sqrt() * eps) / abar_t.sqrt()
    if clip_sample:
        x0_hat = x0_hat.clamp(-clip_sample_range, clip_sample_range)
    sigma = eta * ((1.0 - abar_prev) / (1.0 - abar_t) * (1.0 - abar_t / abar_prev)).sqrt()
    x_prev = abar_prev.sqrt() * x0_hat + (1.0 - abar_prev - sigma ** 2).sqrt() * eps
    if eta > 0:
        x_prev = x_prev + sigma * noise
    # END SOLUTION
    return x_prev


def ddpm_step(eps: torch.Tensor, x_t: torch.Tensor, abar_t: Scalar, abar_prev: Scalar,
              noise: torch.Tensor | None = None, clip_sample: bool = True,
              clip_sample_range: float = 1.0) -> torch.Tensor:
    """One DDPM ancestral step: the posterior mean q(x_prev | x_t, x0_hat) plus fixed_small noise.

        beta      = 1 - abar_t / abar_prev               (the effective beta across the jump)
        mean      = sqrt(abar_prev) beta / (1 - abar_t) * x0_hat
                    + sqrt(1 - beta) (1 - abar_prev) / (1 - abar_t) * x_t     (Ho et al. eq. 7)
        variance  = (1 - abar_prev) / (1 - abar_t) * beta   ("fixed_small", beta-tilde)
        x_prev    = mean + sqrt(variance) * noise           (noise None -> no noise: last step)

    Args as in ``ddim_step``; ``noise`` None means "add no noise" (the sampler passes None at t = 0).
    """
    abar_t = torch.as_tensor(abar_t, dtype=x_t.dtype, device=x_t.device)
    abar_prev = torch.as_tensor(abar_prev, dtype=x_t.dtype, device=x_t.device)
    alpha = abar_t / abar_prev
    beta = 1.0 - alpha
    x0_hat = predict_x0(eps, x_t, abar_t)
    if clip_sample:
        x0_hat = x0_hat.clamp(-clip_sample_range, clip_sample_range)
    mean = (abar_prev.sqrt() * beta / (1.0 - abar_t)) * x0_hat \
        + (alpha.sqrt() * (1.0 - abar_prev) / (1.0 - abar_t)) * x_t
    if noise is None:
        return mean
    # Clamp as diffusers does: beta-tilde is 0 at t = 0 of the full chain.
    variance = ((1.0 - abar_prev) / (1.0 - abar_t) * beta).clamp(min=1e-20)
    return mean + variance.sqrt() * noise


def _randn_like(x: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
    """Standard normal like x, drawn on the generator's device (as diffusers' randn_tensor does)."""
    device = generator.device if generator is not None else x.device
    return torch.randn(x.shape, generator=generator, device=device, dtype=x.dtype).to(x.device)


def _infer_device(eps_model: EpsModel, cond: Any, x_T: torch.Tensor | None) -> torch.device:
    """x_T's device, else cond's, else the model's parameters', else cpu."""
    if x_T is not None:
        return x_T.device
    if torch.is_tensor(cond):
        return cond.device
    params = eps_model.parameters() if isinstance(eps_model, torch.nn.Module) else iter(())
    first = next(params, None)
    return first.device if first is not None else torch.device("cpu")


class _Sampler:
    """Shared timestep bookkeeping and the sampling loop; subclasses define ``step``."""

    def __init__(self, schedule: NoiseSchedule, num_inference_steps: int,
                 clip_sample: bool, clip_sample_range: float, timestep_spacing: str = "leading") -> None:
        T = schedule.num_train_timesteps
        if not isinstance(num_inference_steps, int) or not 1 <= num_inference_steps <= T:
            raise ValueError(f"num_inference_steps must be an int in [1, T={T}], got {num_inference_steps!r}")
        if clip_sample_range <= 0:
            raise ValueError(f"clip_sample_range must be > 0, got {clip_sample_range!r}")
        self.schedule = schedule
        self.num_inference_steps = num_inference_steps
        self.clip_sample = clip_sample
        self.clip_sample_range = clip_sample_range
        if timestep_spacing not in TIMESTEP_SPACINGS:
            raise ValueError(f"timestep_spacing must be one of {TIMESTEP_SPACINGS}, got {timestep_spacing!r}")
        self.timestep_spacing = timestep_spacing
        self.step_ratio = T // num_inference_steps
        if timestep_spacing == "leading":  # diffusers "leading": t_i = i * (T // n), walked from the top down
            self.timesteps = (torch.arange(num_inference_steps) * self.step_ratio).flip(0)  # (n,) long
        else:  # "trailing": round(T - i T / n) - 1 for i = 0..n-1 (diffusers' formula, float steps)
            ts = torch.round(torch.arange(T, 0, -T / num_inference_steps, dtype=torch.float64)) - 1
            self.timesteps = ts.long()[:num_inference_steps]  # (n,) long

    def previous_timestep(self, t: int) -> int:
        """The timestep after t in the walk (negative past the last step, meaning abar = 1)."""
        return int(t) - self.step_ratio

    def _abars(self, t: int) -> tuple[torch.Tensor, torch.Tensor]:
        ac = self.schedule.alphas_cumprod
        prev = self.previous_timestep(t)
        return ac[int(t)], (ac[prev] if prev >= 0 else torch.tensor(1.0))

    def step(self, eps: torch.Tensor, t: int, x_t: torch.Tensor, noise: torch.Tensor | None = None,
             generator: torch.Generator | None = None) -> torch.Tensor:
        raise NotImplementedError

    @torch.no_grad()
    def sample(self, eps_model: EpsModel, shape: tuple[int, ...], cond: Any = None,
               generator: torch.Generator | None = None, device: Any = None,
               x_T: torch.Tensor | None = None, return_trajectory: bool = False):
        """Draw samples by running the reverse chain from pure noise.

        Args:
            eps_model: ``(x_t (B, ...), t (B,) long, cond) -> eps_hat (B, ...)``; put it in eval mode.
            shape: sample shape, e.g. (B, Tp, Da).
            cond: passed to ``eps_model`` unchanged (e.g. global_cond (B, cond_dim)).
            generator: torch.Generator for x_T and the step noise (reproducible by seed).
            device: where x lives; defaults to x_T's device, else cond's, else the model's, else cpu.
            x_T: starting noise (shape ``shape``); drawn from ``generator`` when None.
            return_trajectory: also return every intermediate x, (n+1, *shape), x_T first.

        Returns:
            x0 of shape ``shape`` (normalised units), or ``(x0, trajectory)``.
        """
        if device is None:
            device = _infer_device(eps_model, cond, x_T)
        if x_T is None:
            gen_device = generator.device if generator is not None else device
            x = torch.randn(tuple(shape), generator=generator, device=gen_device).to(device)
        else:
            if tuple(x_T.shape) != tuple(shape):
                raise ValueError(f"x_T has shape {tuple(x_T.shape)}, expected {tuple(shape)}")
            x = x_T.to(device)
        traj = [x] if return_trajectory else None
        B = x.shape[0]
        for t in self.timesteps.tolist():
            t_batch = torch.full((B,), t, dtype=torch.long, device=device)  # (B,)
            eps = eps_model(x, t_batch, cond)
            x = self.step(eps, t, x, generator=generator)
            if traj is not None:
                traj.append(x)
        if traj is not None:
            return x, torch.stack(traj)  # (n+1, *shape)
        return x


class DDPMSampler(_Sampler):
    """Ancestral DDPM sampling with "fixed_small" variance (Diffusion Policy's simulation sampler).

    ``num_inference_steps`` None means T steps (the full chain); fewer steps jump T // n at a time
    with the effective beta across the jump, exactly like diffusers' DDPMScheduler.
    """

    def __init__(self, schedule: NoiseSchedule, num_inference_steps: int | None = None,
                 clip_sample: bool = True, clip_sample_range: float = 1.0) -> None:
        n = schedule.num_train_timesteps if num_inference_steps is None else num_inference_steps
        super().__init__(schedule, n, clip_sample, clip_sample_range)

    def step(self, eps: torch.Tensor, t: int, x_t: torch.Tensor, noise: torch.Tensor | None = None,
             generator: torch.Generator | None = None) -> torch.Tensor:
        """x_t -> x_prev. Noise is ``noise`` if given, else drawn from ``generator``; none at t = 0."""
        abar_t, abar_prev = self._abars(t)
        if int(t) > 0 and noise is None:
            noise = _randn_like(eps, generator)
        elif int(t) == 0:
            noise = None
        return ddpm_step(eps, x_t, abar_t, abar_prev, noise=noise, clip_sample=self.clip_sample,
                         clip_sample_range=self.clip_sample_range)


class DDIMSampler(_Sampler):
    """DDIM sampling in ``num_inference_steps`` steps (Diffusion Policy's fast sampler, 8-16 steps).

    ``step_fn`` (default ``ddim_step``) computes one update
    ``step_fn(eps, x_t, abar_t, abar_prev, eta=, noise=, clip_sample=, clip_sample_range=)``;
    pass a student's implementation here. ``timestep_spacing``: "leading" (90, 80, ..., 0 for
    10 steps; Diffusion Policy's setting) or "trailing" (99, 89, ..., 9); see the module docstring.
    """

    def __init__(self, schedule: NoiseSchedule, num_inference_steps: int = 10, eta: float = 0.0,
                 clip_sample: bool = True, clip_sample_range: float = 1.0,
                 step_fn: Callable[..., torch.Tensor] | None = None, timestep_spacing: str = "leading") -> None:
        super().__init__(schedule, num_inference_steps, clip_sample, clip_sample_range, timestep_spacing)
        if not eta >= 0.0:
            raise ValueError(f"eta must be >= 0, got {eta!r}")
        self.eta = float(eta)
        self.step_fn = ddim_step if step_fn is None else step_fn

    def step(self, eps: torch.Tensor, t: int, x_t: torch.Tensor, noise: torch.Tensor | None = None,
             generator: torch.Generator | None = None) -> torch.Tensor:
        """x_t -> x_prev. With eta > 0 the noise is ``noise`` if given, else drawn from ``generator``."""
        abar_t, abar_prev = self._abars(t)
        if self.eta > 0 and noise is None:
            noise = _randn_like(eps, generator)
        return self.step_fn(eps, x_t, abar_t, abar_prev, eta=self.eta, noise=noise,
                            clip_sample=self.clip_sample, clip_sample_range=self.clip_sample_range)
