"""A checkpoint's weights file: reproducible safetensors bytes that say what they were saved with.

``write_safetensors`` writes the tensors with a ``__metadata__`` header in sorted order (identical
tensors and metadata -> identical bytes, so a recorded SHA-256 is reproducible). A coursekit
checkpoint's metadata is ``{"format", "policy_type", "config_sha256"}``: the policy type and the
digest (:func:`config_digest`) of the policy_type, config and normalisers the weights were trained
with. :func:`check_weights_binding` compares that against a checkpoint's config.json, so the
weights refuse a config.json edited by hand, or one belonging to other weights, even when its own
recorded hashes were recomputed. safetensors cannot hold code; nothing here unpickles.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

FORMAT = "coursekit-checkpoint"
"""The ``format`` of a checkpoint's config.json and of its weights' metadata."""


def file_sha256(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes (read in 1 MiB blocks)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def config_digest(info: dict[str, Any]) -> str:
    """SHA-256 of the canonical JSON of what rebuilds the policy: info's policy_type, config, normalizers."""
    bound = {k: info[k] for k in ("policy_type", "config", "normalizers")}
    return hashlib.sha256(json.dumps(bound, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def write_safetensors(tensors: dict[str, Any], path: str | Path, metadata: dict[str, str]) -> None:
    """safetensors bytes with the metadata in sorted order: identical tensors -> identical file.

    ``safetensors.torch.save`` orders the tensors deterministically but writes ``__metadata__``
    in a hash map's order, which changes from process to process; the header is re-written here
    with sorted keys (the data offsets are relative to the data section, so they stay valid).
    """
    from safetensors.torch import save

    raw = save(tensors)
    n = int.from_bytes(raw[:8], "little")
    header = json.loads(raw[8:8 + n])
    header = {"__metadata__": dict(sorted(metadata.items())), **header}
    text = json.dumps(header, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 8)  # the data section stays 8-byte aligned
    with open(path, "wb") as fh:
        fh.write(len(text).to_bytes(8, "little") + text)
        fh.write(raw[8 + n:])


def check_weights_binding(info: dict[str, Any], metadata: dict[str, str], weights: str) -> None:
    """Refuse (ValueError) weights whose own metadata disagrees with the config.json ``info``.

    ``metadata`` is the ``__metadata__`` of the weights file ``weights``: its policy type must be
    config.json's, and its config digest the one recomputed from config.json now. Weights written
    before the digest went into the metadata (the shipped checkpoints) carry the policy type only;
    config.json's ``weights.config_sha256`` must then be present (the loader checks its value).
    """
    saved_type = metadata.get("policy_type")
    if metadata.get("format") != FORMAT or not saved_type:
        raise ValueError(f"{weights!r} carries no coursekit metadata (format, policy_type): these weights were not "
                         f"saved by coursekit.checkpoint.save_checkpoint, so they cannot be checked against config.json")
    if saved_type != info["policy_type"]:
        raise ValueError(f"{weights!r} holds the weights of a {saved_type!r} policy but config.json says "
                         f"{info['policy_type']!r}: weights from another checkpoint")
    saved_digest, now = metadata.get("config_sha256"), config_digest(info)
    if saved_digest is None and info["weights"].get("config_sha256") is None:
        raise ValueError(f"{weights!r} predates the config digest in its metadata and config.json lacks "
                         f"weights.config_sha256, so config.json cannot be checked against the weights: restore the "
                         f"entry (or the original config.json)")
    if saved_digest is not None and saved_digest != now:
        raise ValueError(f"{weights!r} was saved with another policy_type/config/normalizers than config.json's "
                         f"(config_sha256 in the weights' metadata {saved_digest[:12]}... vs {now[:12]}... now): "
                         f"config.json edited or from another checkpoint")
