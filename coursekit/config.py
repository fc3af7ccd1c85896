"""Typed dataclass configs <-> plain JSON dicts, strictly (checkpoints store configs as JSON).

``config_to_dict`` turns a (possibly nested) dataclass into JSON-ready values; ``config_from_dict``
rebuilds it and refuses anything that is not exactly what the dataclass declares, with a
ValueError that names the field (``UNetChunkConfig.unet.down_dims[1]``), the value and the type
expected:

- every field must be present (a default is NOT filled in: a checkpoint written by another version
  of a policy is reported, never silently mis-read), and no unknown field may appear;
- every value must have its declared type: a ``bool`` is ``true``/``false`` (never ``"false"`` or
  ``0``), an ``int`` is an integer (never a bool), a ``float`` is a number, a ``str`` a string,
  ``tuple[int, ...]`` a list of ints (rebuilt as a tuple), ``X | None`` either, and a nested
  dataclass a dict checked the same way.

Range checks stay where they belong: in each config's ``__post_init__``.
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


def _type_name(tp: Any) -> str:
    if tp is type(None):
        return "null"
    if isinstance(tp, type) and not typing.get_args(tp):
        return tp.__name__
    return str(tp).replace("typing.", "")


def _convert(value: Any, tp: Any, where: str) -> Any:
    """``value`` checked against the annotation ``tp`` (converted: lists -> tuples, dicts -> dataclasses)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None:
            if type(None) in args:
                return None
        else:
            errors = []
            for arg in (a for a in args if a is not type(None)):
                try:
                    return _convert(value, arg, where)
                except ValueError as exc:
                    errors.append(exc)
            if len(errors) == 1:
                raise errors[0]
        raise ValueError(f"{where}: expected {_type_name(tp)}, got {value!r} ({type(value).__name__})")
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return _from_dict(tp, value, where)
    if tp is tuple or origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"{where}: expected a list ({_type_name(tp)}), got {value!r} ({type(value).__name__})")
        if len(args) == 2 and args[1] is Ellipsis:
            types_ = [args[0]] * len(value)
        elif args:
            if len(value) != len(args):
                raise ValueError(f"{where}: expected a list of {len(args)} ({_type_name(tp)}), got {value!r}")
            types_ = list(args)
        else:
            types_ = [Any] * len(value)
        return tuple(_convert(v, t, f"{where}[{i}]") for i, (v, t) in enumerate(zip(value, types_)))
    if origin is list:
        if not isinstance(value, list):
            raise ValueError(f"{where}: expected a list ({_type_name(tp)}), got {value!r} ({type(value).__name__})")
        return [_convert(v, args[0] if args else Any, f"{where}[{i}]") for i, v in enumerate(value)]
    ok = {
        bool: lambda v: isinstance(v, bool),
        int: lambda v: isinstance(v, int) and not isinstance(v, bool),
        float: lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
        str: lambda v: isinstance(v, str),
        type(None): lambda v: v is None,
    }.get(tp)
    if ok is None:
        raise TypeError(f"{where}: config_from_dict cannot check the annotation {tp!r}")
    if not ok(value):
        raise ValueError(f"{where}: expected {_type_name(tp)}, got {value!r} ({type(value).__name__})")
    return float(value) if tp is float else value


def _from_dict(cls: type[C], data: Any, where: str) -> C:
    if not isinstance(data, dict):
        raise ValueError(f"{where}: expected a dict of {cls.__name__} fields, got {data!r} ({type(data).__name__})")
    hints = typing.get_type_hints(cls)
    fields = [f.name for f in dataclasses.fields(cls) if f.init]
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ValueError(f"{where} has no field(s) {unknown}; known fields: {sorted(fields)}")
    missing = [n for n in fields if n not in data]
    if missing:
        raise ValueError(f"{where}: missing field(s) {missing} (every field must be given; defaults are not filled in)")
    kwargs = {name: _convert(data[name], hints[name], f"{where}.{name}") for name in fields}
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from exc


def config_from_dict(cls: type[C], data: dict[str, Any]) -> C:
    """Rebuild a ``cls`` dataclass from :func:`config_to_dict` output, strictly (see module docstring).

    Raises ValueError naming the field, the bad value and the expected type for a missing or
    unknown field or a value of the wrong type; ``cls.__post_init__``'s own ValueError otherwise.
    """
    return _from_dict(cls, data, cls.__name__)
