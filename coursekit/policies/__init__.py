"""Chunk policies: Diffusion Policy, the regression baseline, ACT, flow matching; and the type registry.

Every policy follows the contract in :mod:`coursekit.policies.base`. ``POLICY_TYPES`` maps the
``policy_type`` stored in a checkpoint to its class (as a "module:Class" string, imported on
demand), which is how ``coursekit.checkpoint.load_checkpoint`` rebuilds a policy without
unpickling anything.
"""

from __future__ import annotations

import importlib
from typing import Any

POLICY_TYPES: dict[str, str] = {
    "diffusion": "coursekit.policies.diffusion:DiffusionPolicy",
    "regression": "coursekit.policies.regression:RegressionPolicy",
    "act": "coursekit.policies.act:ACTPolicy",
    "flow": "coursekit.policies.flow:FlowMatchingPolicy",
}

_LAZY = {
    "ChunkPolicy": "coursekit.policies.base:ChunkPolicy",
    "DiffusionPolicy": "coursekit.policies.diffusion:DiffusionPolicy",
    "DiffusionPolicyConfig": "coursekit.policies.diffusion:DiffusionPolicyConfig",
    "RegressionPolicy": "coursekit.policies.regression:RegressionPolicy",
    "RegressionPolicyConfig": "coursekit.policies.regression:RegressionPolicyConfig",
    "ACTPolicy": "coursekit.policies.act:ACTPolicy",
    "ACTConfig": "coursekit.policies.act:ACTConfig",
    "FlowMatchingPolicy": "coursekit.policies.flow:FlowMatchingPolicy",
    "FlowMatchingPolicyConfig": "coursekit.policies.flow:FlowMatchingPolicyConfig",
}
__all__ = sorted(_LAZY) + ["POLICY_TYPES", "get_policy_class"]


def _resolve(target: str) -> Any:
    module, _, name = target.partition(":")
    return getattr(importlib.import_module(module), name)


def get_policy_class(policy_type: str) -> type:
    """The class registered for ``policy_type`` ('diffusion', 'regression', 'act', 'flow')."""
    if policy_type not in POLICY_TYPES:
        raise ValueError(f"unknown policy type {policy_type!r}; expected one of {sorted(POLICY_TYPES)}")
    return _resolve(POLICY_TYPES[policy_type])


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'coursekit.policies' has no attribute {name!r}")
    return _resolve(_LAZY[name])
