"""A toy data set with two modes: action chunks that go round the T on the left or on the right.

Chapters 2-4 study the diffusion loss, the U-Net and the samplers on this stand-in for PushT
demonstrations before chapter 5 uses real ones. It keeps the essential feature of PushT, two
equally good routes from one start (Chi et al. 2023, Fig. 3), and nothing else: each chunk is
Tp pusher targets [x, y] in world pixels (512 x 512, y down) that leave the pusher below the T,
swing round one side of it and end above it.

Diffusion works on normalised actions in [-1, 1] (the samplers' ``clip_sample`` range), so the
chunks are min-max scaled by the world size with the policies' own ``MinMaxNormalizer``:
:func:`pixels_to_unit` and :func:`unit_to_pixels`.
"""

from __future__ import annotations

import numpy as np

from coursekit.data.normalize import MinMaxNormalizer

TWO_ROUTE_SCENE = (256.0, 440.0, 256.0, 250.0, 0.0)
"""The scene the routes go round: [agent_x, agent_y, block_x, block_y, block_angle] (pixels, rad)."""
WORLD_SIZE = 512.0
"""Side of the PushT world in pixels; pixels_to_unit maps [0, WORLD_SIZE] to [-1, 1]."""


def route_chunks(n: int, rng: np.random.Generator, horizon: int = 16, p_left: float = 0.5,
                 scene=TWO_ROUTE_SCENE) -> tuple[np.ndarray, np.ndarray]:
    """Sample ``n`` chunks round the T.

    Args:
        n: number of chunks.
        rng: numpy Generator (the chunks are a deterministic function of its state).
        horizon: Tp, targets per chunk.
        p_left: probability of the left route (0.5: the two modes equally likely).
        scene: [agent_x, agent_y, block_x, block_y, angle]; the routes start at the agent.

    Returns:
        chunks (n, Tp, 2) in world pixels, and side (n,): -1.0 = left, +1.0 = right.
    """
    if not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n must be a positive int, got {n!r}")
    if not 0.0 <= p_left <= 1.0:
        raise ValueError(f"p_left must be a probability in [0, 1], got {p_left!r}")
    if not isinstance(horizon, (int, np.integer)) or horizon < 2:
        raise ValueError(f"horizon (Tp) must be an int >= 2, got {horizon!r}")
    agent_x, agent_y = float(scene[0]), float(scene[1])
    side = np.where(rng.random(n) < p_left, -1.0, 1.0)  # (n,)
    s = np.linspace(0.0, 1.0, horizon)  # (Tp,) progress along the route
    bulge = rng.uniform(120.0, 170.0, size=n)  # (n,) how wide each route swings
    x = agent_x + side[:, None] * bulge[:, None] * np.sin(np.pi * s)[None, :]  # (n, Tp)
    y = agent_y + (90.0 - agent_y) * s[None, :] + rng.normal(0, 4.0, size=(n, 1))  # (n, Tp)
    chunks = np.stack([x, y], axis=-1) + rng.normal(0.0, 3.0, size=(n, horizon, 2))  # (n, Tp, 2)
    return chunks, side


def world_normalizer() -> MinMaxNormalizer:
    """The policies' min-max normaliser, fitted to the world: [0, WORLD_SIZE] -> [-1, 1] per axis."""
    return MinMaxNormalizer(low=np.zeros(2), high=np.full(2, WORLD_SIZE))


def pixels_to_unit(px):
    """World pixels (..., 2) -> a float32 torch tensor in [-1, 1] (the samplers' range)."""
    import torch

    return torch.as_tensor(world_normalizer().normalize(np.asarray(px, dtype=np.float64)), dtype=torch.float32)


def unit_to_pixels(x) -> np.ndarray:
    """A tensor (or array) in [-1, 1] -> world pixels as a numpy array (detached, on the CPU)."""
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return world_normalizer().unnormalize(np.asarray(x, dtype=np.float64))
