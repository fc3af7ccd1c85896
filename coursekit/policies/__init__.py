"""Chunk policies: Diffusion Policy, the regression baseline, ACT, flow matching; the type registry and ``make_policy``.

Every policy follows the contract in :mod:`coursekit.policies.base`. ``POLICY_TYPES`` maps the
``policy_type`` stored in a checkpoint to its class (as a "module:Class" string, imported on
demand), which is how ``coursekit.checkpoint.load_checkpoint`` rebuilds a policy without
unpickling anything, and how ``make_policy`` and ``coursekit train --policy`` find it.

Adding a policy type is ONE entry in ``POLICY_TYPES`` below (plus its module): a ChunkPolicy
subclass with ``policy_type``, ``config_class``, ``recipes``, ``make_config``/``make_batcher``
(or a base that has them, e.g. ``UNetChunkPolicy``) and ``predict_chunk``. The command line,
``make_policy``, checkpoints and every task's evaluation then take it as they are.
"""

from __future__ import annotations

import importlib

from coursekit.lazy import lazy_loader

POLICY_TYPES: dict[str, str] = {
    "diffusion": "coursekit.policies.diffusion:DiffusionPolicy",
    "regression": "coursekit.policies.regression:RegressionPolicy",
    "act": "coursekit.policies.act:ACTPolicy",
    "flow": "coursekit.policies.flow:FlowMatchingPolicy",
}
"""policy_type -> "module:Class": THE place where a policy type is registered."""

_LAZY = {
    "ChunkPolicy": "coursekit.policies.base",
    "DiffusionPolicy": "coursekit.policies.diffusion",
    "DiffusionPolicyConfig": "coursekit.policies.diffusion",
    "RegressionPolicy": "coursekit.policies.regression",
    "RegressionPolicyConfig": "coursekit.policies.regression",
    "ACTPolicy": "coursekit.policies.act",
    "ACTConfig": "coursekit.policies.act",
    "FlowMatchingPolicy": "coursekit.policies.flow",
    "FlowMatchingPolicyConfig": "coursekit.policies.flow",
    "make_policy": "coursekit.policies.factory",
    "PolicySetup": "coursekit.policies.factory",
}
__all__ = sorted(_LAZY) + ["POLICY_TYPES", "get_policy_class"]
__getattr__, __dir__ = lazy_loader(__name__, _LAZY)


def get_policy_class(policy_type: str) -> type:
    """The class registered for ``policy_type`` (a key of :data:`POLICY_TYPES`)."""
    if policy_type not in POLICY_TYPES:
        raise ValueError(f"unknown policy type {policy_type!r}; expected one of {sorted(POLICY_TYPES)}")
    module, _, name = POLICY_TYPES[policy_type].partition(":")
    return getattr(importlib.import_module(module), name)
