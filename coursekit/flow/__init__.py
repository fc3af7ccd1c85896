"""Flow matching on action chunks (chapter 10, §10.3): a velocity objective and an ODE sampler.

The convention throughout is pi0's (Black et al. 2024): time runs from t = 1 (pure Gaussian
noise e) to t = 0 (a data chunk a0) along the straight path

    x_t = t * e + (1 - t) * a0          velocity  u = dx_t/dt = e - a0

The network v_theta(x_t, t, o) regresses u (:mod:`coursekit.flow.loss`); sampling integrates
dx/dt = v_theta from x_1 = e down to t = 0 with Euler (or midpoint) steps
(:mod:`coursekit.flow.sampler`). ``coursekit.policies.flow.FlowMatchingPolicy`` puts both on
Diffusion Policy's U-Net, data and chunking.
"""

from coursekit.flow.loss import TIME_SAMPLINGS, flow_loss, flow_matching_loss, sample_flow_time
from coursekit.flow.sampler import METHODS, euler_step, integrate, midpoint_step

__all__ = ["METHODS", "TIME_SAMPLINGS", "euler_step", "flow_loss", "flow_matching_loss", "integrate",
           "midpoint_step", "sample_flow_time"]
