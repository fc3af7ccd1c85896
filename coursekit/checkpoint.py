"""Policy checkpoints: a directory with ``model.safetensors`` + ``config.json``; never a pickle.

Layout::

    CKPT/
      model.safetensors   the policy's state_dict (tensors only; safetensors cannot hold code)
      config.json         {"format": "coursekit-checkpoint", "format_version": 1,
                           "policy_type": "diffusion" | "regression" | "act" | "flow",
                           "config": {...the policy's dataclass config...},
                           "normalizers": {name: {"kind": "minmax", "state": {"low": [...], ...}}},
                           "dataset": {...dataset meta...}, "training": {...training summary...},
                           "weights": {"file": "model.safetensors", "sha256": "...", "n_tensors": N,
                                       "n_parameters": P, "config_sha256": "..."}, "coursekit_version": "..."}

The weights are bound to the policy_type, config and normalisers they were trained with (the
SHA-256 of their canonical JSON, ``config_sha256``) in both files: config.json's
``weights.config_sha256`` and the weights' own safetensors metadata (``coursekit.weights_file``),
so an edited config.json (a horizon that still fits the tensors' shapes, a deleted
``config_sha256``, weights swapped in from a flow or regression checkpoint with every sha
recomputed) is refused. Weights saved before the digest went into their metadata (the shipped
checkpoints) carry the policy type only; for those config.json's digest is required. Identical
tensors and config give a byte-identical weights file, so the recorded sha256 is reproducible.

Writing is atomic at the directory level: both files go into a hidden staging directory beside
CKPT, which is then exchanged with CKPT in one step (``coursekit.outputs.replace_dir``), so a
reader, or a process killed at any moment, sees the old checkpoint or the new one. The write
holds CKPT's lock (the caller's, e.g. ``coursekit train``'s on its run folder, or its own), which
records the staging directory, so a killed write's leftovers are removed by the next one. Other files in
CKPT (a training run's metrics.csv and loss.png) are carried over, never deleted.
The policy types are the keys of ``coursekit.policies.POLICY_TYPES`` (the one registry).
Loading rebuilds the policy from its registered class and config (``coursekit.policies``), checks
the weights' SHA-256 against config.json, then every tensor name and shape against the freshly
built policy, and refuses anything else (a config field missing, unknown or of the wrong type, a
weights file outside the checkpoint directory) with a :class:`CheckpointError` (a ValueError) that says
what is wrong. ``torch.load`` is never used.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
from pathlib import Path
from typing import Any

from coursekit.output_lock import OutputLock, lock_output
from coursekit.outputs import replace_dir, staging_dir
from coursekit.weights_file import FORMAT, check_weights_binding, config_digest, file_sha256, write_safetensors

FORMAT_VERSION = 1
WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"


class CheckpointError(ValueError):
    """A checkpoint that is missing, corrupt, truncated or does not match the policy it claims."""


def save_checkpoint(policy: Any, path: str | os.PathLike, *, dataset_meta: dict[str, Any] | None = None,
                    training: dict[str, Any] | None = None, half: bool = False,
                    lock: OutputLock | None = None) -> Path:
    """Write ``policy`` (a ChunkPolicy) to the directory ``path`` atomically; returns the path.

    ``dataset_meta`` (e.g. ``EpisodeDataset.meta``) and ``training`` (the trainer's summary) are
    stored verbatim in config.json; they must be JSON-serialisable. ``half=True`` stores float
    tensors as float16 (half the size, for checkpoints shipped in the repository); loading casts
    them back to the policy's float32 parameters. ``lock``: the caller's lock on ``path`` (or on
    the run folder ``path`` is staged for); default: ``path`` is locked for the write.
    """
    if not getattr(policy, "policy_type", ""):
        raise ValueError(f"save_checkpoint needs a policy with a policy_type, got {type(policy).__name__}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tensors = {k: v.detach().to("cpu").contiguous().clone() for k, v in policy.state_dict().items()}
    if half:
        tensors = {k: v.half() if v.is_floating_point() else v for k, v in tensors.items()}
    with contextlib.ExitStack() as stack:
        if lock is None:
            lock = stack.enter_context(lock_output(path))  # also removes what a killed earlier write left
        check_replaceable(path)
        _write_staged(policy, path, tensors, lock, dataset_meta=dataset_meta, training=training, half=half)
    return path


def _write_staged(policy: Any, path: Path, tensors: dict[str, Any], lock: OutputLock, *,
                  dataset_meta: dict[str, Any] | None, training: dict[str, Any] | None, half: bool) -> None:
    """Both files into a recorded staging directory beside ``path``, then one exchange with ``path``.

    The config digest goes into the weights' own metadata as well as config.json, so that loading
    can tell weights from another checkpoint or an edited config (``weights_file.check_weights_binding``).
    """
    import coursekit
    from coursekit.config import config_to_dict
    from coursekit.policies.base import normalizers_to_json

    info = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "policy_type": policy.policy_type,
        "config": config_to_dict(policy.config),
        "normalizers": normalizers_to_json(policy.normalizers),
        "dataset": dataset_meta or {},
        "training": training or {},
        "coursekit_version": coursekit.__version__,
    }
    digest = config_digest(info)
    with staging_dir(path, lock) as tmp:
        weights = tmp / WEIGHTS_FILE
        write_safetensors(tensors, weights, {"format": FORMAT, "policy_type": policy.policy_type,
                                              "config_sha256": digest})
        info["weights"] = {"file": WEIGHTS_FILE, "sha256": file_sha256(weights), "n_tensors": len(tensors),
                           "dtype": "float16" if half else "float32",
                           "n_parameters": int(sum(p.numel() for p in policy.parameters())), "config_sha256": digest}
        (tmp / CONFIG_FILE).write_text(json.dumps(info, indent=1, sort_keys=True) + "\n")
        umask = os.umask(0)
        os.umask(umask)
        for f in (weights, tmp / CONFIG_FILE):
            with open(f, "rb") as fh:
                os.fsync(fh.fileno())
            os.chmod(f, 0o666 & ~umask)  # ordinary file modes whatever wrote them
        os.chmod(tmp, 0o777 & ~umask)
        _keep_foreign_files(path, tmp)  # a run's metrics.csv, loss.png, ... are carried over, never deleted
        replace_dir(tmp, path, lock)  # atomic: path is the old checkpoint or the new one, never neither


def is_checkpoint_dir(path: str | os.PathLike) -> bool:
    """True if ``path`` is a directory holding a readable coursekit checkpoint (config.json of the format)."""
    try:
        read_checkpoint_info(path)
    except (ValueError, OSError):
        return False
    return True


def check_replaceable(path: str | os.PathLike) -> None:
    """Refuse (ValueError) to write a checkpoint where it would replace something that is not one.

    ``path`` may be new, or a directory; other files in it are carried over by the save, but a
    ``config.json`` or ``model.safetensors`` already there must belong to a coursekit checkpoint
    (a user's own files of those names are never replaced).
    """
    path = Path(path)
    if not path.exists() and not path.is_symlink():
        return
    if path.is_symlink() or not path.is_dir():
        raise ValueError(f"{str(path)!r} exists and is not a directory; a checkpoint is a directory: choose another path")
    taken = [n for n in (CONFIG_FILE, WEIGHTS_FILE) if (path / n).exists() or (path / n).is_symlink()]
    if taken and not is_checkpoint_dir(path):
        raise ValueError(f"{str(path)!r} holds {' and '.join(taken)} that are not a coursekit checkpoint's; "
                         f"refusing to replace them: choose another path")


def _keep_foreign_files(path: Path, tmp: Path) -> None:
    """Carry every entry of ``path`` that is not the checkpoint's own (a run's metrics.csv, loss.png, ...)
    into the new directory ``tmp`` before the swap, so re-saving a checkpoint deletes nothing else.

    Files are hard-linked (the same inode: a writer holding one open keeps writing into the new
    directory), or copied where the filesystem has no hard links; folders are copied. Nothing is
    moved, so a failed save leaves CKPT exactly as it was.
    """
    if not path.is_dir():
        return
    for entry in path.iterdir():
        if entry.name in (WEIGHTS_FILE, CONFIG_FILE):
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.copytree(entry, tmp / entry.name, symlinks=True)
            continue
        try:
            os.link(entry, tmp / entry.name, follow_symlinks=False)
        except OSError:
            shutil.copy2(entry, tmp / entry.name, follow_symlinks=False)


def copy_checkpoint_half(src: str | os.PathLike, dest: str | os.PathLike) -> Path:
    """Re-save the checkpoint ``src`` at ``dest`` with float16 weights (how checkpoints are shipped in
    the repository), keeping its dataset metadata and training summary; returns ``dest``."""
    info = read_checkpoint_info(src)
    return save_checkpoint(load_checkpoint(src, device="cpu"), dest, half=True, dataset_meta=info.get("dataset"),
                           training=info.get("training"))


def read_checkpoint_info(path: str | os.PathLike) -> dict[str, Any]:
    """The parsed, format-checked config.json of a checkpoint directory (no weights loaded)."""
    path = Path(path)
    if not path.is_dir():
        raise FileNotFoundError(f"checkpoint directory not found: {str(path)!r} "
                                f"(expected a directory with {WEIGHTS_FILE} and {CONFIG_FILE})")
    cfg = path / CONFIG_FILE
    if not cfg.is_file():
        raise FileNotFoundError(f"checkpoint {str(path)!r} has no {CONFIG_FILE}")
    try:
        info = json.loads(cfg.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{str(cfg)!r} is not valid JSON ({exc}); the checkpoint is corrupt") from exc
    if not isinstance(info, dict) or info.get("format") != FORMAT:
        raise CheckpointError(f"{str(cfg)!r} is not a coursekit checkpoint (format={info.get('format') if isinstance(info, dict) else None!r})")
    if info.get("format_version") != FORMAT_VERSION:
        raise CheckpointError(f"{str(cfg)!r} has format_version {info.get('format_version')!r}; this coursekit reads {FORMAT_VERSION}")
    for key in ("policy_type", "config", "normalizers", "weights"):
        if key not in info:
            raise CheckpointError(f"{str(cfg)!r} lacks the {key!r} entry")
    for key, kind in _ENTRY_TYPES.items():
        if (key in info or key not in _OPTIONAL) and not isinstance(info.get(key), kind):
            raise CheckpointError(f"{str(cfg)!r}: {key!r} must be a JSON {_JSON_NAME[kind]}, got {_short(info.get(key))} "
                                  f"({type(info.get(key)).__name__}); the checkpoint is corrupt or hand-edited")
    return info


# config.json's entries and the JSON type each must have (dataset and training may be absent)
_ENTRY_TYPES = {"policy_type": str, "config": dict, "normalizers": dict, "weights": dict, "dataset": dict, "training": dict}
_OPTIONAL = ("dataset", "training")
_JSON_NAME = {str: "string", dict: "object"}


def _short(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def training_budget(info: dict[str, Any] | str | os.PathLike) -> dict[str, Any]:
    """How much training is behind a checkpoint: steps and wall-clock time, whole history included.

    A run that continued from another (``training["init_from"]``, e.g. the shipped PushT model:
    20 minutes, then 40 more) records each segment separately; this sums the chain.

    Args:
        info: a checkpoint directory or its parsed config.json (``read_checkpoint_info``).

    Returns:
        {"steps": int | None, "seconds": float | None, "minutes": float | None, "segments": int};
        None where a segment did not record the figure.
    """
    if not isinstance(info, dict):
        info = read_checkpoint_info(info)
    segment, segments, steps, seconds = info.get("training") or None, 0, 0, 0.0
    while isinstance(segment, dict) and segments < 100:  # a chain, never a cycle: cap it anyway
        segments += 1
        steps = None if steps is None or segment.get("steps") is None else steps + int(segment["steps"])
        seconds = None if seconds is None or segment.get("seconds") is None else seconds + float(segment["seconds"])
        segment = segment.get("init_from")
    if segments == 0:
        steps = seconds = None
    return {"steps": steps, "seconds": seconds, "minutes": None if seconds is None else seconds / 60.0,
            "segments": segments}


def load_checkpoint(path: str | os.PathLike, device: Any = "auto", expected_type: str | None = None) -> Any:
    """Rebuild the policy saved in ``path`` (in eval mode, on ``device``); refuse anything inconsistent.

    Args:
        path: checkpoint directory.
        device: "auto", "cpu", "cuda", ... (``coursekit.device.resolve_device``).
        expected_type: if given, the checkpoint's policy_type must equal it.
    """
    from coursekit.device import resolve_device

    path = Path(path)
    info = read_checkpoint_info(path)
    cls, config, normalizers = _policy_parts(path, info, expected_type)
    tensors = _read_weights(path, info)
    policy = cls(config, normalizers)
    expected = policy.state_dict()
    missing, unexpected = sorted(set(expected) - set(tensors)), sorted(set(tensors) - set(expected))
    if missing or unexpected:
        raise CheckpointError(f"checkpoint {str(path)!r} does not fit {cls.__name__}: missing tensors {missing[:5]}, "
                              f"unexpected tensors {unexpected[:5]}")
    for name, t in tensors.items():
        if tuple(t.shape) != tuple(expected[name].shape):
            raise CheckpointError(f"checkpoint {str(path)!r}: tensor {name!r} has shape {tuple(t.shape)}, "
                                  f"the config builds {tuple(expected[name].shape)}")
    policy.load_state_dict(tensors, strict=True)  # copies (and casts float16 storage) into the parameters
    return policy.to(resolve_device(device)).eval()


def _policy_parts(path: Path, info: dict[str, Any], expected_type: str | None) -> tuple[type, Any, dict[str, Any]]:
    """The registered class, its config and the normalisers config.json describes (nothing built yet)."""
    from coursekit.config import config_from_dict
    from coursekit.policies import get_policy_class
    from coursekit.policies.base import normalizers_from_json

    ptype = info["policy_type"]
    if expected_type is not None and ptype != expected_type:
        raise CheckpointError(f"checkpoint {str(path)!r} holds a {ptype!r} policy, expected {expected_type!r}")
    try:
        cls = get_policy_class(ptype)
    except ValueError as exc:
        raise CheckpointError(f"checkpoint {str(path)!r}: {exc}") from exc
    try:
        return cls, config_from_dict(cls.config_class, info["config"]), normalizers_from_json(info["normalizers"])
    except (ValueError, TypeError) as exc:
        raise CheckpointError(f"checkpoint {str(path)!r} has a config that does not fit {cls.__name__}: {exc}") from exc


def _read_weights(path: Path, info: dict[str, Any]) -> dict[str, Any]:
    """The tensors of the weights file config.json names, once its name, SHA-256 and config binding check out."""
    from safetensors import SafetensorError, safe_open
    from safetensors.torch import load_file

    entry = info["weights"]
    name = entry.get("file", WEIGHTS_FILE) if isinstance(entry, dict) else None
    if not isinstance(name, str) or Path(name).name != name or name in ("", ".", ".."):
        raise CheckpointError(f"checkpoint {str(path)!r}: weights.file must name a file inside the checkpoint "
                              f"directory (like {WEIGHTS_FILE!r}), got {name!r}")
    bound = entry.get("config_sha256")
    if bound is not None and bound != config_digest(info):
        raise CheckpointError(f"checkpoint {str(path)!r}: config.json's policy_type/config/normalizers differ from those "
                              f"the weights were saved with (config_sha256 mismatch): edited or from another checkpoint")
    weights = path / name
    if weights.is_symlink() or not weights.is_file():
        raise FileNotFoundError(f"checkpoint {str(path)!r} has no weights file {name!r} (a regular file, not a link)")
    digest = file_sha256(weights)
    if digest != entry.get("sha256"):
        raise CheckpointError(f"{str(weights)!r} does not match config.json (sha256 {digest[:12]}... vs "
                              f"{str(entry.get('sha256'))[:12]}...): truncated, corrupt or from another checkpoint")
    try:
        tensors = load_file(str(weights))
        saved_with = safe_open(str(weights), framework="pt").metadata() or {}
    except (SafetensorError, OSError, ValueError) as exc:
        raise CheckpointError(f"{str(weights)!r} cannot be read as safetensors ({exc})") from exc
    try:
        check_weights_binding(info, saved_with, str(weights))
    except ValueError as exc:
        raise CheckpointError(str(exc)) from None
    return tensors


class CheckpointSaver:
    """A training callback that writes the policy to ``path`` at every ``on_checkpoint`` (atomically).

    ``dataset_meta`` is stored beside the trainer's summary (``training`` in config.json).
    """

    def __init__(self, path: str | os.PathLike, dataset_meta: dict[str, Any] | None = None,
                 lock: OutputLock | None = None) -> None:
        self.path, self.dataset_meta, self.lock = Path(path), dataset_meta, lock
        """``lock``: the run's lock (its temporaries are recorded there), or None to lock each write."""

    def on_checkpoint(self, policy: Any, summary: dict[str, Any]) -> None:
        save_checkpoint(policy, self.path, dataset_meta=self.dataset_meta, training=dict(summary), lock=self.lock)


def warm_start(policy: Any, path: str | os.PathLike) -> dict[str, Any]:
    """Copy the weights of the checkpoint ``path`` into ``policy``; returns that checkpoint's provenance.

    The checkpoint must hold the same policy type with the same config and the same normalisers
    (i.e. it was trained on the same kind of data): anything else is refused with the difference.
    Only weights carry over; the optimiser state does not (checkpoints do not store it), so the
    continued run starts a fresh warm-up + schedule. Pass the result to ``train(init_from=...)``.
    """
    from coursekit.config import config_to_dict
    from coursekit.policies.base import normalizers_to_json

    source = load_checkpoint(path, device=policy.device, expected_type=policy.policy_type)
    mine, theirs = config_to_dict(policy.config), config_to_dict(source.config)
    diff = {k: (theirs.get(k), mine.get(k)) for k in sorted(set(mine) | set(theirs)) if mine.get(k) != theirs.get(k)}
    if diff:
        raise CheckpointError(f"--init-from {str(path)!r}: its config differs from this run's as (checkpoint, run): {diff}")
    if normalizers_to_json(source.normalizers) != normalizers_to_json(policy.normalizers):
        raise CheckpointError(f"--init-from {str(path)!r}: its normalisers differ from those fitted on {policy.policy_type} "
                              f"training data here; warm-start only on the same demonstrations")
    policy.load_state_dict(source.state_dict())
    training = read_checkpoint_info(path).get("training") or {}
    keys = ("steps", "seconds", "samples_per_s", "torch_threads", "init_from")
    return {"path": str(path), **{k: training.get(k) for k in keys}}


SHIPPED_DIR = Path(__file__).resolve().parent / "checkpoints"
"""The checkpoints shipped with the package (float16 weights; see the README's results table)."""


def shipped_checkpoints() -> list[str]:
    """Names of the checkpoints shipped in ``coursekit/checkpoints/``."""
    return sorted(p.name for p in SHIPPED_DIR.iterdir() if (p / CONFIG_FILE).is_file()) if SHIPPED_DIR.is_dir() else []


def find_checkpoint(*names: str, also_in: tuple[str | os.PathLike, ...] = ()) -> Path | None:
    """The first checkpoint called one of ``names`` among the shipped ones, then in the folders ``also_in``.

    E.g. ``find_checkpoint("act_transfer_cube", also_in=("outputs/checkpoints",))``: the shipped
    checkpoint if there is one, else one trained by a benchmark; None when there is none (a
    notebook then trains a stand-in).
    """
    for folder in (SHIPPED_DIR, *map(Path, also_in)):
        for name in names:
            if (folder / name / CONFIG_FILE).is_file():
                return folder / name
    return None
