"""Networks: FiLM, the conditional 1-D temporal U-Net, and the GroupNorm image encoder (imports torch)."""

from coursekit.nn.film import FiLM
from coursekit.nn.unet1d import (
    Conv1dBlock,
    ConditionalResidualBlock1D,
    ConditionalUnet1D,
    SinusoidalPosEmb,
    UNet1DConfig,
)
from coursekit.nn.vision import (
    SpatialSoftmax,
    VisionEncoder,
    VisionEncoderConfig,
    center_crop,
    random_crop,
    spatial_softmax,
)

__all__ = ["Conv1dBlock", "ConditionalResidualBlock1D", "ConditionalUnet1D", "FiLM", "SinusoidalPosEmb",
           "SpatialSoftmax", "UNet1DConfig", "VisionEncoder", "VisionEncoderConfig", "center_crop",
           "random_crop", "spatial_softmax"]
