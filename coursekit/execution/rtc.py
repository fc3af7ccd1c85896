"""Real-time chunking (RTC; Black, Galliker and Levine 2025): the next chunk as an inpainting problem.

While chunk k executes, chunk k + 1 is generated from the observation at step r and arrives at
r + d. Its first d actions (steps r .. r + d - 1) are COMMITTED: the robot executes chunk k's
actions there whatever the policy says. RTC generates chunk k + 1 so that it agrees with them:
during denoising (DDIM) or flow integration (Euler) each iterate x is pulled toward the target
Y (chunk k's actions for the same steps) with soft weights W over the overlap::

    j (step r + j):   0 ... d-1 | d ......................... L-1 | L ... Tp-1
    W_j:              1 (frozen) | c_j (e^c_j - 1) / (e - 1)       | 0 (free)
                                   c_j = (L - j) / (L - d + 1), decaying from ~1 to ~0

where L is how far chunk k reaches past r (RTC paper, eq. 5, with H - s = L). Guidance follows
pseudo-inverse guided diffusion (PiGDM, Song et al. 2023): estimate the clean chunk x0_hat(x)
from the current iterate, and add the vector-Jacobian product

    g = (d x0_hat / d x)^T  W (Y - x0_hat)          (through the network, by autograd)

to the update, with a guidance weight clipped at beta = 5 (RTC's choice). How g enters the
update depends on the sampler:

DDIM / DDPM on epsilon (Diffusion Policy; :func:`epsilon_guidance_scale`)::

    x0_hat = (x_t - sqrt(1 - abar_t) eps) / sqrt(abar_t)              (unclipped: the clamp has no gradient)
    eps'   = eps - sqrt(abar_t) * min(beta, 1 / sqrt(abar_t (1 - abar_t))) * g
    x_prev = the policy's own sampler step with eps'                    (DDIM, or DDPM)

Unclipped this is PiGDM exactly: score = -eps / sqrt(1 - abar_t), and PiGDM adds g / r_t^2 to
the score with r_t^2 = 1 - abar_t, i.e. eps' = eps - g / sqrt(1 - abar_t). The clip is RTC's, on
the same quantity RTC clips: rescaled, x_t is a flow iterate at tau = sqrt(abar) / (sqrt(abar) +
sqrt(1 - abar)), where RTC's weight (1 - tau) / (tau r^2) equals 1 / sqrt(abar (1 - abar)).
(Clipping 1 / r_t^2 itself instead would all but switch guidance off in the last, low-noise
steps, where 1 / r_t^2 is in the hundreds and the chunk takes its final shape.)

Euler on velocity (flow matching, pi0's convention: x_t = t e + (1 - t) a0, t = 1 noise, v = e - a0;
:func:`velocity_guidance_weight`)::

    x0_hat = x_t - t v
    v'     = v - min(beta, ((1 - t)^2 + t^2) / ((1 - t) t)) * g
    x_next = the policy's own Euler step with v',   dt = -1/N

which is RTC's Algorithm 1 written in this convention (their tau = 1 - t runs toward the data,
their velocity is -v, and (1 - tau) / (tau r^2) with r^2 = (1 - tau)^2 / (tau^2 + (1 - tau)^2)
becomes the weight above; at t = 1 it is infinite and the clip takes over).

This module holds all of RTC that does not depend on a network: the weights, the two guidance
weights, the VJP, the guided update, the sampling loop over a :class:`GuidedHead`, the executor,
and the chapter's strategies by name. The weights (:func:`rtc_weights`), the VJP
(:func:`guidance_vjp`) and the update (:func:`guided_update`) are exercise "rtc_step" (11.2):
the library's sampler calls these very functions. Each iterative policy provides its own head, built on its own sampler step
(``DiffusionPolicy.guided_head``, ``FlowMatchingPolicy.guided_head``), and the shared
``predict_inpainted`` (:class:`coursekit.policies.unet_chunk.IterativeUNetPolicy`) runs it.

Deliberate choices: the frozen prefix is ALSO copied verbatim into the returned chunk (those
actions are executed from the old chunk anyway, so the chunk says what really happens); with
d = 0 nothing is committed and, by default, the chunk is sampled without guidance, so RTC at
d = 0 is exactly receding-horizon execution (``guide_without_delay=True`` keeps the soft part).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from coursekit.execution.delay import AsyncChunking, DelayedEnsemble, Synchronous
from coursekit.execution.receding import stack_history, to_numpy

MAX_GUIDANCE = 5.0
"""beta: RTC clips the guidance weight at 5."""
WEIGHT_SCHEDULES = ("exp", "hard")
"""Guidance weights: "exp" (RTC's soft decay over the overlap) or "hard" (the frozen prefix only)."""
PREFIX_MODES = ("guide", "replace")
"""The frozen prefix: "guide" (RTC: held by guidance with W = 1) or "replace" (also written into the
iterate at every step, at that step's noise level: Diffusion Policy's inpainting, Chi et al. 2023)."""


def rtc_weights(n: int, delay: int, overlap: int, schedule: str = "exp") -> np.ndarray:
    """Guidance weights W (n,) over the steps r .. r + n - 1 of the next chunk (RTC paper, eq. 5).

    For j = 0 .. n - 1 (step r + j)::

        W_j = 1                                   j < d        (frozen: already committed)
        W_j = c_j (e^c_j - 1) / (e - 1)           d <= j < L   (soft, "exp" only; 0 for "hard")
              with c_j = (L - j) / (L - d + 1)                  (decays from ~1 at j = d to ~0)
        W_j = 0                                   j >= L       (free: the previous chunk has ended)

    Args:
        n: number of weights (target steps).
        delay: d, steps frozen to the committed actions (W = 1).
        overlap: L, steps the previous chunk still covers from r (the soft region is d <= j < L;
            empty when L <= d).
        schedule: "exp" (RTC's exponential decay) or "hard" (frozen prefix only; the ablation
            the paper says jumps at the switch).

    Returns:
        W, a float64 numpy array of shape (n,).
    """
    for name, v in (("n", n), ("delay", delay), ("overlap", overlap)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ValueError(f"{name} must be an integer >= 0, got {v!r}")
    if schedule not in WEIGHT_SCHEDULES:
        raise ValueError(f"schedule must be one of {WEIGHT_SCHEDULES}, got {schedule!r}")
    # BEGIN SOLUTION
    w = np.zeros(n)
    j = np.arange(n)
    w[j < delay] = 1.0
    if schedule == "exp":
        soft = (j >= delay) & (j < overlap)
        c = (overlap - j[soft]) / (overlap - delay + 1.0)
        w[soft] = c * np.expm1(c) / (math.e - 1.0)
    # END SOLUTION
    return w


def guidance_vjp(clean_fn: Callable[[Any], tuple[Any, Any]], x: Any, target: Any, weights: Any) -> tuple[Any, Any, Any]:
    """x0_hat, the model's output, and the guidance g = (d x0_hat / d x)^T [W (Y - x0_hat)], all (B, Tp, Da).

    The weighted error e = W (Y - x0_hat) (W_j multiplies row j of every sample, every action
    dimension) is how far the clean estimate is from the previous chunk where it matters; g is e
    carried back through the network to the iterate: the vector-Jacobian product J^T e (one
    backward pass, ``torch.autograd.grad`` with ``grad_outputs=e``; never the Jacobian itself).
    g is the direction in x that brings x0_hat toward Y (the gradient of -1/2 sum_j W_j
    |Y_j - x0_hat_j|^2 with W held fixed): a small step x + eps g moves x0_hat toward Y.

    Args:
        clean_fn: ``clean_fn(x) -> (x0_hat, model_output)``, each (B, Tp, Da), differentiable in x.
        x: the iterate (B, Tp, Da).
        target: Y (B, Tp, Da), the previous chunk's actions (anything where W = 0).
        weights: W (Tp,) (zero where there is no target).

    Returns:
        (x0_hat, model_output, g), detached tensors of shape (B, Tp, Da).
    """
    import torch

    with torch.enable_grad():
        x = x.detach().requires_grad_(True)
        x0_hat, out = clean_fn(x)
        # BEGIN SOLUTION
        err = (target - x0_hat.detach()) * weights.view(1, -1, 1)  # (B, Tp, Da), W (Y - x0_hat)
        (g,) = torch.autograd.grad(x0_hat, x, grad_outputs=err)  # J^T err, one backward pass
        # END SOLUTION
    return x0_hat.detach(), out.detach(), g


def guided_update(out: Any, g: Any, scale: float) -> Any:
    """One guided update of the model's output: out' = out - scale * g, (B, Tp, Da).

    ``out`` is what the network predicted at this step (flow: the velocity v; diffusion: the
    noise eps), ``g`` the guidance of :func:`guidance_vjp` and ``scale`` >= 0 the sampler's
    guidance weight (:func:`velocity_guidance_weight`, :func:`epsilon_guidance_scale`). The sign:
    both v and eps point from the data toward the noise (x0_hat = x_t - t v; x0_hat = (x_t -
    sqrt(1 - abar) eps) / sqrt(abar)), and the sampler steps AGAINST them (Euler's dt = -1/N), so
    taking scale * g off the output moves the next iterate along +g, toward the previous chunk
    (RTC's Algorithm 1, where the velocity points the other way, adds it instead). The sampler
    then takes its own step with out'.

    Args:
        out: the model output (B, Tp, Da).
        g: the guidance (B, Tp, Da).
        scale: the guidance weight, a float >= 0 (already clipped at beta).

    Returns:
        out' (B, Tp, Da).
    """
    # BEGIN SOLUTION
    return out - scale * g
    # END SOLUTION


def epsilon_guidance_scale(abar: float, max_guidance: float) -> float:
    """sqrt(abar) * min(beta, 1 / sqrt(abar (1 - abar))): the factor of g subtracted from eps (module docstring)."""
    if abar >= 1.0:
        return 0.0
    return abar ** 0.5 * min(float(max_guidance), 1.0 / (abar * (1.0 - abar)) ** 0.5)


def velocity_guidance_weight(t: float, max_guidance: float) -> float:
    """min(beta, ((1 - t)^2 + t^2) / ((1 - t) t)): the factor of g subtracted from v; infinite (so beta) at t = 1."""
    if t >= 1.0 or t <= 0.0:
        return float(max_guidance)
    return min(float(max_guidance), ((1.0 - t) ** 2 + t ** 2) / ((1.0 - t) * t))


class GuidedHead(Protocol):
    """A policy's sampler seen one step at a time: what DDIM/DDPM (diffusion) and Euler (flow) both provide."""

    num_steps: int
    """Network calls from noise to a chunk."""

    def clean(self, x: Any, k: int) -> tuple[Any, Any]:
        """Step k: the clean-chunk estimate x0_hat(x) (B, Tp, Da) and the model output (eps or v)."""

    def guidance_scale(self, k: int, max_guidance: float) -> float:
        """Step k: the weight of g in :func:`guided_update` (clipped at ``max_guidance``)."""

    def step(self, x: Any, k: int, model_out: Any, g: Any, max_guidance: float) -> Any:
        """Step k: the next iterate from x and the model output, guided by the VJP g when given:
        the sampler's own step on ``guided_update(model_out, g, self.guidance_scale(k, max_guidance))``."""

    def noised(self, clean: Any, noise: Any, k: int) -> Any:
        """A clean chunk carried to the noise level after step k along ``noise`` (for ``replace``)."""


def sample_guided(head: GuidedHead, x: Any, target: Any, weights: Any, max_guidance: float = MAX_GUIDANCE,
                  replace: Any = None) -> Any:
    """Run ``head`` from noise ``x`` (B, Tp, Da) to a chunk, guided toward ``target`` with ``weights``.

    All-zero weights skip the backward pass: the result is then the plain sampler's, bit for bit.
    ``replace`` (Tp,) bool, optional: after every step those indices of the iterate are overwritten
    by ``head.noised(target, x_start, k)``, the target carried to the step's noise level along its
    own noise (Diffusion Policy's inpainting, Chi et al. 2023; a departure from RTC, which only
    guides; off by default).
    """
    import torch

    guided = bool((weights != 0).any())
    x_start = x
    for k in range(head.num_steps):
        if guided:
            _, out, g = guidance_vjp(lambda z: head.clean(z, k), x, target, weights)
        else:
            with torch.no_grad():
                _, out = head.clean(x, k)
            g = None
        with torch.no_grad():
            x = head.step(x, k, out, g, max_guidance)
            if replace is not None and bool(replace.any()):
                x = torch.where(replace.view(1, -1, 1), head.noised(target, x_start, k), x)
    return x


class RealTimeChunking(AsyncChunking):
    """Asynchronous execution whose next chunk is inpainted onto the committed actions (RTC).

    Same schedule as :class:`~coursekit.execution.delay.AsyncChunking`; at each request after the
    first, the target Y is the current chunk's actions for steps r, r + 1, ... (held past its
    end), the weights come from :func:`rtc_weights`, and ``predict_inpainted(obs_history,
    target (B, n, Da), weights (n,), frozen=d, max_guidance=beta, prefix=...) -> (B, Tp, Da)``
    generates the chunk (index ``start + j`` of the chunk is aligned with ``target[:, j]``). Its
    first d actions are then set to the committed ones exactly.

    Args (besides DelayedExecutor's):
        predict_inpainted: the guided sampler, a policy's ``predict_inpainted`` bound to its
            noise generator and sampling options (``coursekit.evaluate.evaluate`` binds it); required.
        schedule: "exp" (RTC) or "hard" (frozen prefix only).
        max_guidance: beta, the clip of the guidance weight (RTC: 5).
        prefix: "guide" (RTC) or "replace" (Diffusion Policy's inpainting), see :data:`PREFIX_MODES`.
        guide_without_delay: guide with the soft weights also when d = 0 (default False: d = 0
            is plain receding horizon).
    """

    def __init__(self, predict_chunk: Callable[[Any], Any], n_obs_steps: int = 2, n_action_steps: int = 8,
                 delay: int = 0, start: int | None = None, predict_inpainted: Callable[..., Any] | None = None,
                 schedule: str = "exp", max_guidance: float = MAX_GUIDANCE, prefix: str = "guide",
                 guide_without_delay: bool = False) -> None:
        super().__init__(predict_chunk, n_obs_steps, n_action_steps, delay, start)
        if not callable(predict_inpainted):
            raise ValueError("RealTimeChunking needs predict_inpainted(obs_history, target, weights, frozen=d, ...) "
                             f"(a diffusion or flow policy's guided sampler), got {predict_inpainted!r}")
        if schedule not in WEIGHT_SCHEDULES:
            raise ValueError(f"schedule must be one of {WEIGHT_SCHEDULES}, got {schedule!r}")
        if prefix not in PREFIX_MODES:
            raise ValueError(f"prefix must be one of {PREFIX_MODES}, got {prefix!r}")
        if isinstance(max_guidance, bool) or not (isinstance(max_guidance, (int, float, np.floating))
                                                  and math.isfinite(max_guidance) and max_guidance >= 0):
            raise ValueError(f"max_guidance (beta) must be a finite number >= 0, got {max_guidance!r}")
        self.predict_inpainted = predict_inpainted
        self.schedule = schedule
        self.max_guidance = float(max_guidance)
        self.prefix = prefix
        self.guide_without_delay = bool(guide_without_delay)

    def _compute(self) -> Any:
        cur, d, r = self.current, self.delay, self.t
        if cur is None or (d == 0 and not self.guide_without_delay):
            return super()._compute()
        overlap = max(0, cur.request + cur.length - r)  # steps r .. r + overlap - 1 the current chunk covers
        n = max(d, overlap)
        target = np.stack([to_numpy(cur.action_at(r + j)) for j in range(n)], axis=1)  # (B, n, Da)
        weights = rtc_weights(n, d, overlap, self.schedule)  # (n,)
        chunk = self.predict_inpainted(stack_history(self.history), target, weights, frozen=d,
                                       max_guidance=self.max_guidance, prefix=self.prefix)
        shape = tuple(getattr(chunk, "shape", ()))
        if len(shape) != 3 or shape[0] != target.shape[0] or shape[1] < self.start + d:
            raise ValueError(f"predict_inpainted returned shape {shape}; expected (B={target.shape[0]}, "
                             f"Tp >= start + d = {self.start + d}, Da)")
        committed = target[:, :d]  # (B, d, Da): what the robot executes while this chunk is computed
        if hasattr(chunk, "detach"):
            chunk = chunk.clone()
            chunk[:, self.start:self.start + d] = chunk.new_tensor(committed)
        else:
            chunk = np.array(chunk, copy=True)
            chunk[:, self.start:self.start + d] = committed
        return chunk


STRATEGIES = {"sync": Synchronous, "async": AsyncChunking, "ensemble": DelayedEnsemble, "rtc": RealTimeChunking}
"""Chapter 11's ways of executing chunks under a delay, by name: executor classes built like every
executor, ``cls.from_spec(predict_chunk, spec, delay=d)`` (RTC also takes ``predict_inpainted``)."""
