"""Demonstrations checked against the task they are to train, before any training starts.

A dataset file can be well formed (:meth:`coursekit.data.EpisodeDataset.load` accepts it) and
still be unfit to train a policy for a task: no episode at all, actions of text, a NaN in one
step, or actions one column too wide (a PushT policy with 3-d actions trains happily and fails
only when the 2-d environment receives its first action). :func:`check_training_data` refuses
each with ONE line naming the array, the episode and step, or the width the task takes::

    check_training_data(dataset, "pusht_state", source="--data 'demos.npz'")
    # ValueError: --data 'demos.npz': the data contains NaN at episode 1, step 15 of 'action' (column 1)
"""

from __future__ import annotations

from typing import Any

import numpy as np

from coursekit.data.features import get_features

TASK_ACTION_DIM = {"pusht": 2, "aloha": 14}
"""Width of one action in each world: PushT a target (x, y); the arm pair 14 joint targets (2 x (6 + gripper))."""

_ACTION_NAMES = {"pusht": "target x, y", "aloha": "2 x (6 joints + gripper)"}


def check_training_data(dataset: Any, features: str, source: str = "the dataset") -> None:
    """Refuse (ValueError, one line starting with ``source``) demonstrations unfit to train ``features``' task.

    Args:
        dataset: an :class:`~coursekit.data.EpisodeDataset` ("action" (N, Da) and the arrays the
            features read, e.g. "state" (N, 5) for PushT, "qpos" (N, 14) + "env_state" for the arm pair).
        features: a key of ``coursekit.data.features.FEATURES``; its task fixes the action width.
        source: how the message names the data (the CLI passes ``--data 'path'``).

    Checks, in order: at least one episode; an "action" array and the arrays the features read;
    numbers (not text or booleans) in each; actions of shape (N, Da) with the task's Da; every
    value finite (the first NaN or inf is reported by episode, step and column).
    """
    spec = get_features(features)
    if dataset.n_episodes == 0 or dataset.n_steps == 0:
        raise ValueError(f"{source} holds no episodes (0 steps): nothing to train on")
    needed = ("action", *spec.reads)
    missing = [k for k in needed if k not in dataset.arrays]
    if missing:
        raise ValueError(f"{source} lacks the array(s) {missing} that {features!r} ({spec.task} task) trains on; it has "
                         f"{sorted(dataset.arrays)} (demonstrations of another task?)")
    for key in needed:
        kind = dataset[key].dtype.kind
        if kind not in "iuf":
            raise ValueError(f"{source}: array {key!r} must hold numbers, got dtype {dataset[key].dtype} "
                             f"(first value {str(dataset[key].flat[0])[:30]!r})")
    action = dataset["action"]
    want = TASK_ACTION_DIM.get(spec.task)  # None: task-agnostic features (raw_state) fix no width
    if action.ndim != 2 or (want is not None and action.shape[1] != want):
        if want is None:
            raise ValueError(f"{source}: 'action' has shape {action.shape}; actions must be (N, Da)")
        raise ValueError(f"{source}: 'action' has shape {action.shape}, the {spec.task} task takes actions of "
                         f"shape (N, {want}) ({_ACTION_NAMES[spec.task]}): demonstrations of another task?")
    for key in needed:
        _check_finite(dataset, key, source)


def _check_finite(dataset: Any, key: str, source: str) -> None:
    """The first non-finite value of ``dataset[key]`` (N, ...) as 'episode e, step t', or nothing."""
    values = np.asarray(dataset[key])
    if values.dtype.kind != "f":
        return  # integers are always finite
    bad_rows = ~np.isfinite(values.reshape(len(values), -1)).all(axis=1)  # (N,)
    if not bad_rows.any():
        return
    row = int(np.argmax(bad_rows))
    episode = int(np.searchsorted(dataset.episode_ends, row, side="right"))
    step = row - int(dataset.episode_starts[episode])
    flat = values[row].reshape(-1)
    column = int(np.argmax(~np.isfinite(flat)))
    what = "NaN" if np.isnan(flat[column]) else "inf"
    where = f" (column {column})" if values.ndim > 1 else ""
    raise ValueError(f"{source}: the data contains {what} at episode {episode}, step {step} of {key!r}{where}")
