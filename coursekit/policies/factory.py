"""Build a PushT policy and its training batches from demonstrations, in one call.

    policy, batches = make_pusht_policy("diffusion", dataset, features="pusht_state")
    result = coursekit.train.train(policy, batches, TrainConfig(minutes=20))

The policy's config gets Do/Da from the data, its min-max normalisers are fitted on the data,
and the batcher gathers (B, To, Do) / (B, Tp, Da) windows of the same To/Tp/Ta.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from coursekit.data.batches import WindowBatcher, pusht_training_arrays
from coursekit.data.episodes import EpisodeDataset

UNET_POLICIES = ("diffusion", "regression", "flow")


def make_unet_config(policy_type: str, **kwargs: Any) -> Any:
    """The config dataclass of 'diffusion', 'regression' or 'flow' from keyword fields."""
    if policy_type == "diffusion":
        from coursekit.policies.diffusion import DiffusionPolicyConfig

        return DiffusionPolicyConfig(**kwargs)
    if policy_type == "regression":
        from coursekit.policies.regression import RegressionPolicyConfig

        return RegressionPolicyConfig(**kwargs)
    if policy_type == "flow":
        from coursekit.policies.flow import FlowMatchingPolicyConfig

        return FlowMatchingPolicyConfig(**kwargs)
    raise ValueError(f"policy_type must be one of {UNET_POLICIES}, got {policy_type!r}")


def pusht_image_arrays(dataset: EpisodeDataset, size: tuple[int, int] = (96, 96)) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """PushT demonstrations -> ({"image": (N, 3, H, W) uint8, "agent_pos": (N, 2)}, action (N, 2)).

    Images are rendered from the stored states with the env's own observation renderer (the
    dataset keeps states only; N x 96 x 96 x 3 bytes is about 28 kB per step).
    """
    from coursekit.envs.pusht_render import PushTRenderer

    if "image" in dataset.arrays:
        images = np.asarray(dataset["image"])
        images = images.transpose(0, 3, 1, 2) if images.shape[-1] == 3 else images  # (N, 3, H, W)
    else:
        renderer = PushTRenderer(size)
        images = np.stack([renderer.render(s) for s in dataset["state"]]).transpose(0, 3, 1, 2)  # (N, 3, H, W)
    obs = {"image": np.ascontiguousarray(images, dtype=np.uint8),
           "agent_pos": np.asarray(dataset["state"][:, :2], dtype=np.float32)}  # (N, 2)
    return obs, np.asarray(dataset["action"], dtype=np.float32)


def make_pusht_policy(policy_type: str, dataset: EpisodeDataset, features: str = "pusht_state",
                      batch_size: int = 256, seed: int = 0, device: Any = "cpu",
                      **config_kwargs: Any) -> tuple[Any, WindowBatcher]:
    """A fresh policy (weights seeded by ``seed``, normalisers fitted) and its seeded batcher.

    Args:
        policy_type: 'diffusion', 'regression' or 'flow'.
        dataset: PushT demonstrations with "state" (N, 5) and "action" (N, 2).
        features: 'pusht_state', 'pusht_keypoints' (low-dim) or 'pusht_image'.
        batch_size, seed, device: of the batcher (and the weight initialisation).
        config_kwargs: further config fields (n_action_steps=..., unet=UNet1DConfig(...), ...).
    """
    from coursekit.device import resolve_device

    device = resolve_device(device)
    if features == "pusht_image":
        config = make_unet_config(policy_type, obs_type="image", features=features, obs_dim=2,
                                  action_dim=int(dataset["action"].shape[-1]), **config_kwargs)
        obs, action = pusht_image_arrays(dataset, config.vision.image_size)
    else:
        obs, action = pusht_training_arrays(dataset, features)
        config = make_unet_config(policy_type, features=features, obs_dim=int(obs["obs"].shape[-1]),
                                  action_dim=int(action.shape[-1]), **config_kwargs)
    from coursekit.policies import get_policy_class

    with torch.random.fork_rng(devices=[]):  # seeded init without disturbing the caller's generator
        torch.manual_seed(seed)
        policy = get_policy_class(policy_type)(config)
    policy.fit_normalizers(obs, action)
    policy.to(device)
    batches = WindowBatcher(obs, action, dataset.episode_ends, horizon=config.horizon,
                            n_obs_steps=config.n_obs_steps, n_action_steps=config.n_action_steps,
                            batch_size=batch_size, seed=seed, device=device)
    return policy, batches
