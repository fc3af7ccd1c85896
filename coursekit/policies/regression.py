"""The regression baseline: Diffusion Policy's backbone and data, trained to output the chunk directly.

Same observations, normalisation, U-Net, To/Tp/Ta and training recipe as
:class:`~coursekit.policies.diffusion.DiffusionPolicy`; only the head differs. The U-Net is
called ONCE with a fixed input -- an all-zero "noisy chunk" and diffusion step t = 0 -- and its
output is taken as the normalised action chunk, trained with the mean squared error::

    a_hat = unet(zeros (B, Tp, Da), t = 0, cond = o)          loss = || a_hat - a_0 ||^2

The minimiser of the MSE is the conditional MEAN of the demonstrated chunks. Where the
demonstrations split (go left or right round the T) the mean lies between the two routes, so
the pusher hesitates or freezes there: the failure the paper's multimodality argument predicts
(Chi et al. 2023, Sec. 4.1 and Fig. 3). The same backbone keeps the comparison fair: the score
gap is due to the generative head, not to capacity. Measured here (``benchmarks/bench_claims.py``),
the effect is smaller than that picture: with chunks of 16 targets, DART data and keypoint inputs
the shipped regressor's first chunk at a two-way start goes round one side, and its failures are
later stalls against the block rather than a freeze at the fork.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch
import torch.nn.functional as F

from coursekit.policies.unet_chunk import UNetChunkConfig, UNetChunkPolicy


@dataclass
class RegressionPolicyConfig(UNetChunkConfig):
    """The regression baseline's settings: exactly the shared inputs/U-Net fields (nothing diffusion-specific)."""


class RegressionPolicy(UNetChunkPolicy):
    """Deterministic chunk regression with the Diffusion Policy U-Net (zero input, t = 0)."""

    policy_type = "regression"
    config_class = RegressionPolicyConfig
    config: RegressionPolicyConfig

    def _forward(self, cond: torch.Tensor) -> torch.Tensor:
        """Global condition (B, cond_dim) -> normalised chunk (B, Tp, Da)."""
        c = self.config
        zeros = cond.new_zeros(cond.shape[0], c.horizon, c.action_dim)  # (B, Tp, Da) fixed input
        t = torch.zeros(cond.shape[0], dtype=torch.long, device=cond.device)  # (B,) fixed step 0
        return self.unet(zeros, t, cond)

    def compute_loss(self, batch: Any, **_: Any) -> dict[str, torch.Tensor]:
        """Raw batch {obs keys: (B, To, ...), "action": (B, Tp, Da)} -> {"loss": MSE in normalised units}."""
        cond, action_n = self._batch_parts(batch)  # (B, cond_dim), (B, Tp, Da)
        return {"loss": F.mse_loss(self._forward(cond), action_n)}

    @torch.no_grad()
    def predict_chunk(self, obs_history: Any, *, generator: torch.Generator | None = None) -> Any:
        """Raw history (B, To, Do) (or dict; or unbatched (To, Do)) -> raw chunk (B, Tp, Da).

        Deterministic: ``generator`` is accepted (the shared contract) and unused; there are no
        sampling options.
        """
        self._require_normalizers()
        obs, unbatched = self._obs_dict(obs_history)
        was_training = self.training
        self.eval()
        try:
            chunk_n = self._forward(self.encode_obs(obs)).clamp(-1.0, 1.0)  # (B, Tp, Da), in the data's range
        finally:
            self.train(was_training)
        return self._finish(chunk_n, obs_history, unbatched)
