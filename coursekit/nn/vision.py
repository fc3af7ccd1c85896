"""Image encoder for Diffusion Policy: a ResNet-18-style trunk with GroupNorm and a spatial softmax.

Chi et al. (2023, sec. 3.3): one ResNet-18 per camera, trained from scratch (no ImageNet weights),
global average pooling replaced by a spatial softmax (32 keypoints, as in robomimic / Levine et al.
2016), and every BatchNorm replaced by GroupNorm — BatchNorm's running statistics fight the EMA of the
weights. Augmentation: a random 84x84 crop of the 96x96 image in training, the centre crop in eval.

Departures (flagged): widths are configurable (``VisionEncoderConfig()`` is a narrower CPU version;
``preset("resnet18")`` has ResNet-18's 64/128/256/512); the keypoints go through Linear -> ReLU to
``feature_dim`` as in LeRobot's port.

``spatial_softmax`` is exercise "spatial_softmax" (12.1); ``SpatialSoftmax(..., keypoints_fn=...)`` and
``VisionEncoder(..., keypoints_fn=...)`` take a student's version.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn


def _pair(v, name: str) -> tuple[int, int]:
    pair = (v, v) if isinstance(v, int) else tuple(v)
    if len(pair) != 2 or any(not isinstance(x, int) or x < 1 for x in pair):
        raise ValueError(f"{name} must be a positive int or an (H, W) pair of them, got {v!r}")
    return pair


@dataclass(frozen=True)
class VisionEncoderConfig:
    """Sizes of one camera's encoder."""

    in_channels: int = 3
    """Image channels (3 for RGB)."""
    image_size: tuple[int, int] = (96, 96)
    """(H, W) the encoder works at, before cropping."""
    frame_size: tuple[int, int] | None = None
    """(H, W) of the camera frames given, when larger than ``image_size``: each frame is first resized
    to ``image_size`` by area averaging (96 -> 48: each pixel the mean of a 2x2 block). None: the
    frames are ``image_size``. Departure: Diffusion Policy encodes its 96x96 frames at full size."""
    crop_size: tuple[int, int] = (84, 84)
    """Crop (h, w): random in train(), centred in eval(); equal to image_size for no crop."""
    random_crops: bool = True
    """The augmentation: a random crop in train(). False: the centre crop in train() too (the same
    input size, no augmentation; chapter 12 measures what the crops buy)."""
    widths: tuple[int, ...] = (32, 64, 128, 256)
    """Channels of the four residual stages (ResNet-18: 64, 128, 256, 512)."""
    blocks_per_stage: int = 2
    """BasicBlocks per stage (ResNet-18: 2)."""
    group_size: int = 16
    """GroupNorm uses channels // group_size groups (Diffusion Policy's replace_bn_with_gn)."""
    num_keypoints: int = 32
    """K, spatial-softmax keypoints."""
    feature_dim: int = 64
    """Output features per camera."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "image_size", _pair(self.image_size, "image_size"))
        object.__setattr__(self, "crop_size", _pair(self.crop_size, "crop_size"))
        if self.frame_size is not None:
            object.__setattr__(self, "frame_size", _pair(self.frame_size, "frame_size"))
            if any(i > f for i, f in zip(self.image_size, self.frame_size)):
                raise ValueError(f"image_size {self.image_size} must fit in frame_size {self.frame_size} "
                                 f"(frames are only ever shrunk)")
        object.__setattr__(self, "widths", tuple(self.widths))
        if any(c > s for c, s in zip(self.crop_size, self.image_size)):
            raise ValueError(f"crop_size {self.crop_size} must fit in image_size {self.image_size}")
        if not self.widths or any(not isinstance(w, int) or w < self.group_size or w % self.group_size
                                  for w in self.widths):
            raise ValueError(f"widths must be multiples of group_size={self.group_size}, got {self.widths!r}")
        if not isinstance(self.random_crops, bool):
            raise ValueError(f"random_crops must be True or False, got {self.random_crops!r}")
        for name in ("in_channels", "blocks_per_stage", "group_size", "num_keypoints", "feature_dim"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be a positive int, got {v!r}")

    @property
    def input_size(self) -> tuple[int, int]:
        """(H, W) of the frames the encoder takes: ``frame_size``, else ``image_size``."""
        return self.frame_size if self.frame_size is not None else self.image_size

    @classmethod
    def preset(cls, name: str) -> "VisionEncoderConfig":
        """"cpu" (default, narrower), "resnet18" (the paper's widths 64/128/256/512) or "small" (the
        two-stage route of chapter 12: widths 16-128, one block per stage, 96x96 frames encoded at
        48x48 with 42x42 crops; about 6x the images per second of "cpu" on one core, bench_pixels) or
        "arm_pair" (ACT from the arm pair's top camera, 'aloha_image': whole 96x128 frames, no crops as
        ACT trains, three stages of widths 16-64 so that ACT gets a 6 x 8 grid of image tokens; with the
        fourth stage it would get 3 x 4, and from 48x64 frames 2 x 2, where a 4 cm cube is a pixel or two)."""
        small = dict(widths=(16, 32, 64, 128), blocks_per_stage=1)
        presets = {"cpu": cls(), "resnet18": cls(widths=(64, 128, 256, 512)),
                   "small": cls(**small, image_size=(48, 48), crop_size=(42, 42), frame_size=(96, 96)),
                   "arm_pair": cls(widths=(16, 32, 64), blocks_per_stage=1, image_size=(96, 128), crop_size=(96, 128),
                                   random_crops=False)}
        if name not in presets:
            raise ValueError(f"unknown vision preset {name!r}; expected one of {sorted(presets)}")
        return presets[name]


def random_crop(images: torch.Tensor, size, generator: torch.Generator | None = None) -> torch.Tensor:
    """Crop each image of (B, C, H, W) at its own random offset to (B, C, h, w)."""
    h, w = _pair(size, "size")
    B, C, H, W = images.shape
    if h > H or w > W:
        raise ValueError(f"crop {(h, w)} larger than images {(H, W)}")
    gen_device = generator.device if generator is not None else images.device
    top = torch.randint(0, H - h + 1, (B,), generator=generator, device=gen_device).to(images.device)
    left = torch.randint(0, W - w + 1, (B,), generator=generator, device=gen_device).to(images.device)
    rows = (top[:, None] + torch.arange(h, device=images.device))  # (B, h)
    cols = (left[:, None] + torch.arange(w, device=images.device))  # (B, w)
    b = torch.arange(B, device=images.device)[:, None, None]  # (B, 1, 1)
    out = images.permute(0, 2, 3, 1)[b, rows[:, :, None], cols[:, None, :]]  # (B, h, w, C)
    return out.permute(0, 3, 1, 2)  # (B, C, h, w)


def center_crop(images: torch.Tensor, size) -> torch.Tensor:
    """Centre crop (B, C, H, W) -> (B, C, h, w)."""
    h, w = _pair(size, "size")
    H, W = images.shape[-2:]
    if h > H or w > W:
        raise ValueError(f"crop {(h, w)} larger than images {(H, W)}")
    top, left = (H - h) // 2, (W - w) // 2
    return images[..., top:top + h, left:left + w]


def spatial_softmax(maps: torch.Tensor) -> torch.Tensor:
    """The expected image position of each heat map: (B, K, H, W) -> (B, K, 2) as (x, y).

    Levine et al. (2016, "End-to-end training of deep visuomotor policies"): each of the K
    maps becomes a distribution over its own H*W positions,

        p_k(i, j) = exp(m_k(i, j)) / sum_{i', j'} exp(m_k(i', j')),

    and the keypoint is that distribution's mean position,

        x_k = sum_{i, j} p_k(i, j) * x_j,    y_k = sum_{i, j} p_k(i, j) * y_i,

    with x_j = -1 + 2 j / (W - 1) across the width (column j) and y_i = -1 + 2 i / (H - 1) down the
    height (row i): both span [-1, 1] from the first to the last pixel centre, (-1, -1) is the
    top-left pixel. Diffusion Policy (Chi et al. 2023, sec. 3.3) replaces ResNet's global average
    pooling with this, as robomimic does: pooling forgets WHERE a feature fires, a keypoint keeps it.

    Args:
        maps: (B, K, H, W) floating-point heat maps (logits; any real values).

    Returns:
        keypoints: (B, K, 2) of maps' dtype and device, [..., 0] = x, [..., 1] = y.

    Keep it differentiable (torch operations only): the encoder learns its maps through it.
    """
    if not torch.is_tensor(maps) or maps.ndim != 4 or not maps.is_floating_point():
        got = f"{tuple(maps.shape)} {maps.dtype}" if torch.is_tensor(maps) else type(maps).__name__
        raise ValueError(f"spatial_softmax expects a float tensor of heat maps (B, K, H, W), got {got}")
    H, W = maps.shape[-2:]
    # BEGIN SOLUTION
    attn = maps.flatten(2).softmax(dim=-1)  # (B, K, H*W): each map sums to 1 over its positions
    ys, xs = torch.meshgrid(torch.linspace(-1, 1, H, device=maps.device, dtype=maps.dtype),
                            torch.linspace(-1, 1, W, device=maps.device, dtype=maps.dtype), indexing="ij")  # (H, W)
    grid = torch.stack([xs.reshape(-1), ys.reshape(-1)], dim=-1)  # (H*W, 2) as (x, y)
    keypoints = attn @ grid  # (B, K, 2)
    # END SOLUTION
    return keypoints


class SpatialSoftmax(nn.Module):
    """Keypoints from a feature map (Levine et al. 2016): (B, C, H, W) -> (B, K, 2).

    A 1x1 conv makes K heat maps; :func:`spatial_softmax` turns each into the expected (x, y) in
    [-1, 1] of a softmax over its H*W positions. ``keypoints_fn`` replaces that function (a student's
    ``spatial_softmax`` in chapter 12); the default looks the library's up at call time.
    """

    def __init__(self, in_channels: int, num_keypoints: int, keypoints_fn=None) -> None:
        super().__init__()
        self.to_maps = nn.Conv2d(in_channels, num_keypoints, 1)
        self.num_keypoints = num_keypoints
        self.keypoints_fn = keypoints_fn

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        maps = self.to_maps(x)  # (B, K, H, W)
        fn = self.keypoints_fn if self.keypoints_fn is not None else spatial_softmax
        return fn(maps)  # (B, K, 2)


class BasicBlock(nn.Module):
    """ResNet basic block with GroupNorm: two 3x3 convs, identity or 1x1-conv skip."""

    def __init__(self, cin: int, cout: int, stride: int, group_size: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(cin, cout, 3, stride=stride, padding=1, bias=False)
        self.norm1 = nn.GroupNorm(cout // group_size, cout)
        self.conv2 = nn.Conv2d(cout, cout, 3, padding=1, bias=False)
        self.norm2 = nn.GroupNorm(cout // group_size, cout)
        self.skip = nn.Identity()
        if stride != 1 or cin != cout:
            self.skip = nn.Sequential(nn.Conv2d(cin, cout, 1, stride=stride, bias=False),
                                      nn.GroupNorm(cout // group_size, cout))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = F.relu(self.norm1(self.conv1(x)))
        return F.relu(self.norm2(self.conv2(h)) + self.skip(x))


class VisionEncoder(nn.Module):
    """One camera: images (B, C, H, W) in [-1, 1] -> features (B, feature_dim).

    In ``train()`` mode each image is randomly cropped to ``crop_size``; in ``eval()`` the centre crop.
    ``keypoints_fn``: the spatial softmax's (B, K, H, W) -> (B, K, 2) (default :func:`spatial_softmax`).
    """

    def __init__(self, config: VisionEncoderConfig | None = None, keypoints_fn=None) -> None:
        super().__init__()
        self.config = cfg = config if config is not None else VisionEncoderConfig()
        w0 = cfg.widths[0]
        # ResNet stem: 7x7/2 conv, norm, ReLU, 3x3/2 max-pool.
        self.stem = nn.Sequential(nn.Conv2d(cfg.in_channels, w0, 7, stride=2, padding=3, bias=False),
                                  nn.GroupNorm(w0 // cfg.group_size, w0), nn.ReLU(),
                                  nn.MaxPool2d(3, stride=2, padding=1))
        stages, cin = [], w0
        for i, cout in enumerate(cfg.widths):
            for j in range(cfg.blocks_per_stage):
                stride = 2 if (i > 0 and j == 0) else 1
                stages.append(BasicBlock(cin, cout, stride, cfg.group_size))
                cin = cout
        self.stages = nn.Sequential(*stages)
        self.pool = SpatialSoftmax(cin, cfg.num_keypoints, keypoints_fn)
        self.out = nn.Linear(2 * cfg.num_keypoints, cfg.feature_dim)

    def _keypoints(self, images: torch.Tensor, generator: torch.Generator | None = None):
        """Images (B, C, *input_size) in [-1, 1] -> (keypoints (B, K, 2) in [-1, 1] of the last map, its (h', w'))."""
        cfg = self.config
        if images.ndim != 4 or images.shape[1] != cfg.in_channels or tuple(images.shape[-2:]) != cfg.input_size:
            raise ValueError(f"images must be (B, {cfg.in_channels}, {cfg.input_size[0]}, {cfg.input_size[1]}), "
                             f"got {tuple(images.shape)}")
        if cfg.input_size != cfg.image_size:
            images = F.interpolate(images, size=cfg.image_size, mode="area")  # (B, C, *image_size)
        if cfg.crop_size != cfg.image_size:
            images = random_crop(images, cfg.crop_size, generator) if self.training and cfg.random_crops \
                else center_crop(images, cfg.crop_size)  # (B, C, h, w)
        x = self.stages(self.stem(images))  # (B, widths[-1], h', w')
        return self.pool(x), tuple(x.shape[-2:])

    def forward(self, images: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
        keypoints, _ = self._keypoints(images, generator)  # (B, K, 2)
        return F.relu(self.out(keypoints.flatten(1)))  # (B, feature_dim)

    @torch.no_grad()
    def keypoints_in_frame(self, images: torch.Tensor) -> torch.Tensor:
        """Where the encoder looks: its K spatial-softmax keypoints as (x, y) pixels of the input frames.

        ``images``: (B, C, *input_size) in [-1, 1]. Returns (B, K, 2) in continuous pixel coordinates
        of those frames (pixel i spans [i, i + 1]: draw over ``imshow(..., extent=(0, W, H, 0))``),
        from the centre crop of eval mode. A keypoint is the expected position of a heat map over
        the last feature map's cells; each cell is mapped to the centre of the crop pixels it covers.
        """
        cfg = self.config
        was_training = self.training
        self.eval()
        try:
            kp, (h, w) = self._keypoints(images)  # (B, K, 2) in [-1, 1], x first
        finally:
            self.train(was_training)
        (ch, cw), (ih, iw), (fh, fw) = cfg.crop_size, cfg.image_size, cfg.input_size
        x = ((kp[..., 0] + 1) / 2 * (w - 1) + 0.5) * cw / w + (iw - cw) // 2  # (B, K) image px
        y = ((kp[..., 1] + 1) / 2 * (h - 1) + 0.5) * ch / h + (ih - ch) // 2  # (B, K)
        return torch.stack([x * fw / iw, y * fh / ih], dim=-1)  # (B, K, 2) frame px
