"""Typed dataclass configs <-> plain JSON dicts, strictly (checkpoints store configs as JSON).

``config_to_dict`` turns a (possibly nested) dataclass into JSON-ready values; ``config_from_dict``
rebuilds it and refuses unknown or missing fields with a ValueError that names them, so a
checkpoint written by a different version of a policy is reported, never silently mis-read.
Tuples come back as tuples (JSON only knows lists) and nested dataclass fields are rebuilt from
their declared types. Validation stays where it belongs: in each config's ``__post_init__``.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from typing import Any, TypeVar

C = TypeVar("C")


def config_to_dict(config: Any) -> dict[str, Any]:
    """A dataclass instance -> dict of JSON values (nested dataclasses become dicts, tuples lists)."""
    if not dataclasses.is_dataclass(config) or isinstance(config, type):
        raise ValueError(f"config_to_dict expects a dataclass instance, got {config!r}")
    return _jsonable(dataclasses.asdict(config))


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if hasattr(value, "item") and not isinstance(value, (str, bytes)):  # numpy / torch scalars
        return value.item()
    return value


def _dataclass_in(tp: Any) -> type | None:
    """The dataclass type inside an annotation like ``X``, ``X | None`` or ``Optional[X]``, if any."""
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return tp
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        for arg in typing.get_args(tp):
            found = _dataclass_in(arg)
            if found is not None:
                return found
    return None


def _is_tuple(tp: Any) -> bool:
    if typing.get_origin(tp) is tuple or tp is tuple:
        return True
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        return any(_is_tuple(a) for a in typing.get_args(tp))
    return False


def _to_tuple(value: Any) -> Any:
    return tuple(_to_tuple(v) for v in value) if isinstance(value, list) else value


def config_from_dict(cls: type[C], data: dict[str, Any]) -> C:
    """Rebuild a ``cls`` dataclass from :func:`config_to_dict` output; unknown/missing fields -> ValueError."""
    if not isinstance(data, dict):
        raise ValueError(f"{cls.__name__}: expected a dict of fields, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ValueError(f"{cls.__name__} has no field(s) {unknown}; known fields: {sorted(fields)}")
    missing = [n for n, f in fields.items() if n not in data and f.default is dataclasses.MISSING
               and f.default_factory is dataclasses.MISSING]
    if missing:
        raise ValueError(f"{cls.__name__}: missing required field(s) {missing}")
    kwargs = {}
    for name, value in data.items():
        tp = hints.get(name)
        sub = _dataclass_in(tp)
        if sub is not None and isinstance(value, dict):
            kwargs[name] = config_from_dict(sub, value)
        elif _is_tuple(tp) and isinstance(value, list):
            kwargs[name] = _to_tuple(value)
        else:
            kwargs[name] = value
    return cls(**kwargs)
