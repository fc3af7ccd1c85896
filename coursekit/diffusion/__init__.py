"""Diffusion maths: noise schedules, the epsilon loss, and the DDPM / DDIM samplers (imports torch)."""

from coursekit.diffusion.loss import diffusion_loss, epsilon_loss, q_sample
from coursekit.diffusion.samplers import DDIMSampler, DDPMSampler, ddim_step, ddpm_step, predict_x0
from coursekit.diffusion.schedules import BETA_SCHEDULES, NoiseSchedule, cosine_alpha_bar

__all__ = ["BETA_SCHEDULES", "DDIMSampler", "DDPMSampler", "NoiseSchedule", "cosine_alpha_bar",
           "ddim_step", "ddpm_step", "diffusion_loss", "epsilon_loss", "predict_x0", "q_sample"]
