"""Dataset files, property-based: valid ones round-trip exactly, anything else is ONE clear line.

Random valid datasets survive save/load bit for bit. Random npz files (members missing or of the
wrong kind, ``__meta__`` any JSON value, object arrays, float or decreasing episode ends), random
truncations and byte flips of a valid file, and the issue's cases (a ``.npy`` given as data, a
JSON-list ``__meta__``, a directory, a missing file) either load into a consistent dataset or
raise a DatasetError / FileNotFoundError whose single-line message names the file — never a
traceback from deeper down.
"""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from coursekit.data.episodes import DatasetError, EpisodeDataset

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
json_values = st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=5),
                           lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=4), c, max_size=3),
                           max_leaves=6)


def _valid(lengths, dims, meta, seed=0):
    rng = np.random.default_rng(seed)
    eps = [{f"x{i}": rng.normal(size=(n, d)).astype(np.float32) for i, d in enumerate(dims)} for n in lengths]
    return EpisodeDataset.from_episodes(eps, meta)


@SETTINGS
@given(lengths=st.lists(st.integers(1, 6), min_size=1, max_size=4), dims=st.lists(st.integers(1, 3), min_size=1, max_size=3),
       meta=st.dictionaries(st.text(min_size=1, max_size=5).filter(lambda k: k != "format_version"), json_values, max_size=3))
def test_valid_datasets_round_trip_exactly(tmp_path, lengths, dims, meta):
    ds = _valid(lengths, dims, meta)
    back = EpisodeDataset.load(ds.save(tmp_path / "d.npz"))
    np.testing.assert_array_equal(back.episode_ends, ds.episode_ends)
    assert back.meta == {"format_version": 1, **meta} and sorted(back.arrays) == sorted(ds.arrays)
    for k, v in ds.arrays.items():
        np.testing.assert_array_equal(back.arrays[k], v)


def _assert_clear_refusal(path, exc):
    assert isinstance(exc, (DatasetError, FileNotFoundError)), f"{type(exc).__name__}: {exc}"
    assert "\n" not in str(exc) and str(path) in str(exc), str(exc)


def _load_or_clear_refusal(path):
    try:
        ds = EpisodeDataset.load(path)
    except Exception as exc:  # noqa: BLE001 -- the property is about which exceptions escape
        _assert_clear_refusal(path, exc)
        return None
    assert isinstance(ds.meta, dict) and ds.meta["format_version"] == 1
    assert np.all(np.diff(ds.episode_ends) > 0) and (ds.episode_ends[0] > 0 if ds.n_episodes else True)
    assert all(a.shape[:1] == (ds.n_steps,) for a in ds.arrays.values())
    return ds


members = st.fixed_dictionaries({}, optional={
    "__meta__": st.one_of(json_values.map(lambda v: np.array(json.dumps(v))),
                          st.just(np.array(json.dumps({"format_version": 1}))), st.just(np.arange(3)), st.just(np.array("{bad"))),
    "episode_ends": st.one_of(st.lists(st.integers(-2, 8), max_size=4).map(lambda v: np.array(v, dtype=np.int64)),
                              st.just(np.array([2.5, 4.0])), st.just(np.zeros((2, 2), dtype=np.int64)), st.just(np.array([2, 4]))),
    "obs": st.integers(0, 6).map(lambda n: np.zeros((n, 2), np.float32)),
    "junk": st.one_of(st.just(np.array([{"a": 1}, None], dtype=object)), st.just(np.zeros(()))),
})


@SETTINGS
@given(content=members)
def test_any_npz_content_loads_consistently_or_is_refused_in_one_line(tmp_path, content):
    path = tmp_path / "d.npz"
    with open(path, "wb") as fh:
        np.savez(fh, **content)  # np.savez pickles object arrays: exactly what load must refuse
    ds = _load_or_clear_refusal(path)
    if any(v.dtype == object for v in content.values()):
        assert ds is None


@SETTINGS
@given(cut=st.floats(0, 1, exclude_max=True), flips=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(1, 255)), max_size=3))
def test_truncated_or_flipped_files_load_consistently_or_are_refused_in_one_line(tmp_path, cut, flips):
    good = _valid([3, 4], [2], {"env_id": "x"}).save(tmp_path / "good.npz").read_bytes()
    data = bytearray(good if flips else good[: int(cut * len(good))])
    for where, xor in flips:
        data[int(where * len(data))] ^= xor
    path = tmp_path / "bad.npz"
    path.write_bytes(bytes(data))
    _load_or_clear_refusal(path)


def test_the_issue_examples_each_give_one_clear_line(tmp_path):
    np.save(tmp_path / "a.npy", np.zeros(3))
    cases = {tmp_path / "a.npy": r"is a single \.npy array, not a coursekit dataset",
             tmp_path / "list.npz": r"'__meta__' must be a JSON object \(dict\), got a list",
             tmp_path / "obj.npz": r"array 'obs' holds Python objects \(dtype object\)",
             tmp_path: r"is a directory, not a dataset file",
             tmp_path / "text.npz": r"not an \.npz \(zip\) file",
             tmp_path / "other.npz": r"lacks '__meta__'/'episode_ends'"}
    with open(tmp_path / "list.npz", "wb") as fh:
        np.savez(fh, __meta__=np.array(json.dumps([1, 2])), episode_ends=np.array([1]), obs=np.zeros((1, 2)))
    with open(tmp_path / "obj.npz", "wb") as fh:
        np.savez(fh, __meta__=np.array(json.dumps({"format_version": 1})), episode_ends=np.array([1]),
                 obs=np.array([{"a": 1}], dtype=object))
    (tmp_path / "text.npz").write_text("hello")
    buf = io.BytesIO()
    np.savez(buf, weights=np.zeros(2))
    (tmp_path / "other.npz").write_bytes(buf.getvalue())
    for path, match in cases.items():
        with pytest.raises(DatasetError, match=match) as info:
            EpisodeDataset.load(path)
        _assert_clear_refusal(path, info.value)
    with pytest.raises(FileNotFoundError, match="dataset file not found") as info:
        EpisodeDataset.load(tmp_path / "missing.npz")
    _assert_clear_refusal(tmp_path / "missing.npz", info.value)


# ---- demonstrations checked against the task they are to train (coursekit.data.validate) -----------

def _task_data(lengths, task: str, action_width: int | None = None, seed: int = 0) -> EpisodeDataset:
    """Valid demonstrations of ``task`` ('pusht': state (N, 5) + action (N, 2); 'aloha': qpos (N, 14),
    env_state (N, 7), action (N, 14)), optionally with actions of another width."""
    rng = np.random.default_rng(seed)
    width = action_width or {"pusht": 2, "aloha": 14}[task]
    eps = []
    for n in lengths:
        ep = ({"state": rng.uniform(50, 450, (n, 5))} if task == "pusht"
              else {"qpos": rng.normal(size=(n, 14)), "env_state": rng.normal(size=(n, 7))})
        eps.append({**ep, "action": rng.uniform(0, 512, (n, width))})
    return EpisodeDataset.from_episodes(eps, {"env_id": task})


@SETTINGS
@given(lengths=st.lists(st.integers(1, 8), min_size=1, max_size=4), data=st.data(),
       value=st.sampled_from([np.nan, np.inf, -np.inf]), task=st.sampled_from(["pusht", "aloha"]))
def test_a_non_finite_value_is_reported_by_episode_step_and_column(lengths, data, value, task):
    from coursekit.data.validate import check_training_data

    ds = _task_data(lengths, task)
    features = {"pusht": "pusht_state", "aloha": "aloha_state"}[task]
    check_training_data(ds, features)  # valid: no error
    key = data.draw(st.sampled_from(sorted(ds.arrays)))
    episode = data.draw(st.integers(0, len(lengths) - 1))
    step = data.draw(st.integers(0, lengths[episode] - 1))
    column = data.draw(st.integers(0, ds[key].shape[1] - 1))
    ds.arrays[key][int(ds.episode_starts[episode]) + step, column] = value
    what = "NaN" if np.isnan(value) else "inf"
    with pytest.raises(ValueError, match=rf"^--data 'd\.npz': the data contains {what} at episode {episode}, step {step} "
                                         rf"of '{key}' \(column {column}\)$"):
        check_training_data(ds, features, source="--data 'd.npz'")


@SETTINGS
@given(task=st.sampled_from(["pusht", "aloha"]), width=st.integers(1, 16),
       dtype=st.sampled_from(["float32", "float64", "int64", "bool", "<U8"]))
def test_actions_are_accepted_exactly_when_numeric_and_as_wide_as_the_task_takes(task, width, dtype):
    from coursekit.data.validate import TASK_ACTION_DIM, check_training_data

    ds = _task_data([3, 4], task, action_width=width)
    ds.arrays["action"] = ds["action"].astype(dtype)
    features = {"pusht": "pusht_state", "aloha": "aloha_state"}[task]
    if width == TASK_ACTION_DIM[task] and dtype not in ("bool", "<U8"):
        check_training_data(ds, features)
        return
    expected = (r"array 'action' must hold numbers, got dtype" if dtype in ("bool", "<U8")
                else rf"'action' has shape \(7, {width}\), the {task} task takes actions of shape \(N, {TASK_ACTION_DIM[task]}\)")
    with pytest.raises(ValueError, match=expected) as info:
        check_training_data(ds, features)
    assert "\n" not in str(info.value)


def test_an_empty_data_set_or_another_tasks_arrays_are_refused_by_make_policy():
    from coursekit.policies.factory import make_policy

    empty = EpisodeDataset({"state": np.zeros((0, 5)), "action": np.zeros((0, 2))}, np.zeros(0, np.int64), {})
    with pytest.raises(ValueError, match=r"^the dataset holds no episodes \(0 steps\): nothing to train on$"):
        make_policy("diffusion", empty, features="pusht_state")
    with pytest.raises(ValueError, match=r"lacks the array\(s\) \['state'\] that 'pusht_state' \(pusht task\) trains on"):
        make_policy("diffusion", _task_data([5], "aloha"), features="pusht_state")
    with pytest.raises(ValueError, match=r"'action' has shape \(10, 3\), the pusht task takes actions of shape \(N, 2\)"):
        make_policy("regression", _task_data([4, 6], "pusht", action_width=3))
