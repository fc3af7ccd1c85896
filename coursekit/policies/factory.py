"""One call from demonstrations to a policy ready to train: ``make_policy``, for every policy and task.

    policy, batches, recipe = make_policy("diffusion", dataset, features="pusht_keypoints", recipe="cpu")
    result = coursekit.train.train(policy, batches, TrainConfig(**recipe, minutes=20))

The policy type names a class in the registry (:data:`coursekit.policies.POLICY_TYPES`); the
features name a row of the one feature table (:data:`coursekit.data.features.FEATURES`), so any
policy trains on any task. The class itself says the rest: its config from the data's Do / Da
(``make_config``), its normalisers fitted on the data (``fit_normalizers``), its kind of
training sample (``make_batcher``) and its named optimiser recipes (``recipes``).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import torch

from coursekit.data.features import default_features, get_features, training_arrays
from coursekit.data.validate import check_training_data


class PolicySetup(NamedTuple):
    """What :func:`make_policy` returns (unpacks as ``policy, batches, recipe``)."""

    policy: Any
    """A fresh ChunkPolicy: weights seeded, normalisers fitted, on the requested device."""
    batches: Any
    """Its endless, seeded training batches (``WindowBatcher`` or ``ChunkBatcher``)."""
    recipe: dict[str, Any]
    """TrainConfig fields of the named recipe (optimiser, schedule, EMA, batch size); add a budget."""


def make_policy(policy_type: str, dataset: Any, *, features: str | None = None, recipe: str = "paper",
                batch_size: int | None = None, seed: int = 0, device: Any = "cpu", **config: Any) -> PolicySetup:
    """A fresh policy of ``policy_type`` for ``dataset``, its seeded batcher and its training recipe.

    Args:
        policy_type: a key of ``POLICY_TYPES`` ('diffusion', 'regression', 'act', ...).
        dataset: an :class:`~coursekit.data.EpisodeDataset` with "action" and the arrays ``features`` reads.
        features: a key of ``FEATURES`` (default: the default features of the data's task, ``coursekit.tasks``).
        recipe: a key of the class's ``recipes`` ("paper" or "cpu"); sets the batch size unless given.
        batch_size, seed, device: of the batcher (``seed`` also seeds the weight initialisation).
        config: further config fields (n_action_steps=..., unet=UNet1DConfig(...), chunk_size=...,
            ``preset="paper"`` for ACT's paper size, ...).
    """
    from coursekit.device import resolve_device
    from coursekit.policies import get_policy_class

    cls = get_policy_class(policy_type)
    if recipe not in cls.recipes:
        raise ValueError(f"unknown training recipe {recipe!r} for {policy_type!r}; expected one of {sorted(cls.recipes)}")
    train_fields = dict(cls.recipes[recipe])
    if batch_size is not None:
        train_fields["batch_size"] = int(batch_size)
    device = resolve_device(device)
    features = features or default_features(dataset.arrays, dataset.meta)
    check_training_data(dataset, features)  # empty, text, NaN, or actions of another task's width: refused here
    spec = get_features(features)
    low = spec(dataset.arrays)  # (N, Do): the low-dim part (image features: agent_pos)
    cfg = cls.make_config(features=features, obs_type=spec.obs_type, obs_dim=int(low.shape[-1]),
                          action_dim=int(dataset["action"].shape[-1]), **config)
    vision = getattr(cfg, "vision", None)
    obs, action = training_arrays(dataset, features, **({"image_size": vision.input_size} if vision else {}))
    with torch.random.fork_rng(devices=[]):  # seeded init without disturbing the caller's generator
        torch.manual_seed(seed)
        policy = cls(cfg)
    policy.fit_normalizers(obs, action)
    policy.to(device)
    batches = policy.make_batcher(obs, action, dataset.episode_ends, batch_size=train_fields.get("batch_size", 256),
                                  seed=seed, device=device)
    return PolicySetup(policy, batches, train_fields)
