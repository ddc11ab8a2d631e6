"""Messages to and from plain dicts / YAML (the CLI's `topic pub` and `topic echo` forms)."""
from __future__ import annotations

import sys
from typing import Any

import numpy as np
import yaml

from .classes import DTYPES, attr_name
from .spec import FLOATS, INT_RANGES, STRINGS, FieldType


def _plain(value: Any) -> Any:
    if hasattr(value, "_spec"):
        return to_dict(value)
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def to_dict(msg: Any) -> dict:
    """{field: value} with ROS field names; nested messages as dicts, arrays as lists."""
    spec = getattr(msg, "_spec", None)
    if spec is None:
        raise TypeError(f"not a roszen message: {type(msg).__name__}")
    return {f.name: _plain(getattr(msg, attr_name(f.name))) for f in spec.fields}


def to_yaml(msg: Any) -> str:
    """`ros2 topic echo` style block YAML of a message."""
    return yaml.dump(to_dict(msg), sort_keys=False, default_flow_style=False,
                     allow_unicode=True, width=sys.maxsize)


def _type_word(value: Any) -> str:
    return f"{type(value).__name__} {value!r}" if not isinstance(value, (list, dict)) else type(value).__name__


def _scalar(base: str, value: Any, path: str, string_bound: int = 0) -> Any:
    if base == "bool":
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
        raise ValueError(f"field '{path}': expected bool, got {_type_word(value)}")
    if base in FLOATS:
        if isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (str, bytes)):
            return float(value)
        raise ValueError(f"field '{path}': expected float, got {_type_word(value)}")
    if base in STRINGS:
        if not isinstance(value, str):
            raise ValueError(f"field '{path}': expected string, got {_type_word(value)}")
        if string_bound and len(value) > string_bound:
            raise ValueError(f"field '{path}': string longer than its bound {string_bound}")
        return value
    if base in ("byte", "char"):
        if isinstance(value, (bytes, bytearray)) and len(value) == 1:
            value = value[0]
        elif isinstance(value, str) and len(value) == 1 and base == "char":
            value = ord(value)
    if isinstance(value, (int, np.integer)) and not isinstance(value, float):
        lo, hi = INT_RANGES[base]
        v = int(value)
        if not lo <= v <= hi:
            raise ValueError(f"field '{path}': {v} out of range for {base} [{lo}, {hi}]")
        return v
    raise ValueError(f"field '{path}': expected integer ({base}), got {_type_word(value)}")


def _array(t: FieldType, value: Any, path: str, item_cls: type | None = None) -> Any:
    if isinstance(value, (str, dict)) or not hasattr(value, "__len__"):
        raise ValueError(f"field '{path}': expected a list, got {_type_word(value)}")
    n = len(value)
    if t.kind == "array" and n != t.size:
        raise ValueError(f"field '{path}': expected {t.size} elements, got {n}")
    if t.kind == "bseq" and n > t.size:
        raise ValueError(f"field '{path}': at most {t.size} elements allowed, got {n}")
    if t.is_primitive and t.base in DTYPES:
        dtype = DTYPES[t.base]
        if isinstance(value, np.ndarray):
            kind = value.dtype.kind
            ok = {"b": "b", "f": "biuf", "i": "biu", "u": "biu"}[dtype.kind]
            if kind not in ok:
                raise ValueError(f"field '{path}': array of {value.dtype} cannot be {t.base}[]")
            if dtype.kind in "iu" and value.size and kind in "iu":
                lo, hi = INT_RANGES[t.base]
                if value.min() < lo or value.max() > hi:
                    raise ValueError(f"field '{path}': values out of range for {t.base}")
            return np.array(value, dtype=dtype)
        if isinstance(value, (bytes, bytearray)) and dtype == np.uint8:
            return np.frombuffer(bytes(value), dtype=np.uint8).copy()
        items = [_scalar(t.base, v, f"{path}[{i}]") for i, v in enumerate(value)]
        return np.array(items, dtype=dtype)
    if t.is_primitive:
        return [_scalar(t.base, v, f"{path}[{i}]", t.string_bound) for i, v in enumerate(value)]
    return [_nested(item_cls, v, f"{path}[{i}]") for i, v in enumerate(value)]


def _nested(cls: type, value: Any, path: str) -> Any:
    if isinstance(value, cls):
        return _fill(cls, {f.name: getattr(value, attr_name(f.name)) for f in cls._spec.fields}, path)
    if value is None:
        return cls()
    if isinstance(value, dict):
        return _fill(cls, value, path)
    raise ValueError(f"field '{path}': expected a {cls.__msgtype__} mapping, got {_type_word(value)}")


def _fill(cls: type, data: dict, prefix: str) -> Any:
    spec = cls._spec
    by_name = {f.name: f for f in spec.fields}
    for key in data:
        if key not in by_name and not (isinstance(key, str) and key.endswith("_") and key[:-1] in by_name):
            where = f"{prefix}.{key}" if prefix else str(key)
            raise ValueError(
                f"unknown field '{where}' for {spec.name} (fields: {', '.join(by_name) or 'none'})")
    kwargs = {}
    for f in spec.fields:
        a = attr_name(f.name)
        if f.name in data:
            value = data[f.name]
        elif a in data:
            value = data[a]
        else:
            continue
        path = f"{prefix}.{f.name}" if prefix else f.name
        t = f.type
        if t.kind != "scalar":
            kwargs[a] = _array(t, value, path, cls._nested_classes.get(f.name))
        elif t.is_primitive:
            kwargs[a] = _scalar(t.base, value, path, t.string_bound)
        else:
            kwargs[a] = _nested(cls._nested_classes[f.name], value, path)
    return cls(**kwargs)


def from_dict(cls: type, data: Any) -> Any:
    """Build `cls` from a mapping; ValueError naming the field on unknown names or bad values."""
    if data is None:
        return cls()
    if isinstance(data, cls):
        data = {f.name: getattr(data, attr_name(f.name)) for f in cls._spec.fields}
    if not isinstance(data, dict):
        raise ValueError(f"{cls.__msgtype__}: expected a mapping of fields, got {_type_word(data)}")
    return _fill(cls, data, "")


def coerce(msg: Any) -> Any:
    """A validated copy of `msg` with lists turned into typed numpy arrays (serializer fallback)."""
    return from_dict(type(msg), msg)
