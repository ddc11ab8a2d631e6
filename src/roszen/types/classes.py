"""Generated Python message classes: slotted, every field defaulted as rclpy does."""
from __future__ import annotations

import keyword
from typing import Callable

import numpy as np

from .spec import EMPTY_MEMBER, FLOATS, STRINGS, MsgSpec

DTYPES = {
    "bool": np.dtype(np.bool_), "byte": np.dtype(np.uint8), "char": np.dtype(np.uint8),
    "int8": np.dtype(np.int8), "uint8": np.dtype(np.uint8), "int16": np.dtype(np.int16),
    "uint16": np.dtype(np.uint16), "int32": np.dtype(np.int32), "uint32": np.dtype(np.uint32),
    "int64": np.dtype(np.int64), "uint64": np.dtype(np.uint64),
    "float32": np.dtype(np.float32), "float64": np.dtype(np.float64),
}


def attr_name(name: str) -> str:
    """Python attribute for a ROS field name (keywords get a trailing underscore, as rclpy)."""
    return name + "_" if keyword.iskeyword(name) else name


def scalar_default(base: str, default: object) -> object:
    if default is not None:
        return float(default) if base in FLOATS else default
    if base == "bool":
        return False
    if base in FLOATS:
        return 0.0
    if base in STRINGS:
        return ""
    return 0


class _Missing:
    __slots__ = ()

    def __repr__(self) -> str:
        return "<default>"


MISSING = _Missing()


def _msg_eq(self, other) -> bool:
    if type(other) is not type(self):
        return NotImplemented
    for name in self.__slots__:
        a, b = getattr(self, name), getattr(other, name)
        if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
            if not np.array_equal(np.asarray(a), np.asarray(b)):
                return False
        elif a != b:
            return False
    return True


def _msg_repr(self) -> str:
    pkg, kind, name = self.__msgtype__.split("/")
    args = ", ".join(f"{n}={getattr(self, n)!r}" for n in self.__slots__)
    return f"{pkg}.{kind}.{name}({args})"


def make_class(spec: MsgSpec, nested: Callable[[str], type]) -> type:
    """Build the class for `spec`; `nested(name)` returns the class of a nested message type."""
    ns: dict[str, object] = {"_D": MISSING, "_np": np}
    nested_classes: dict[str, type] = {}     # field name -> its message class (types.convert)
    params: list[str] = []
    body: list[str] = []
    for i, f in enumerate(spec.fields):
        a = attr_name(f.name)
        t = f.type
        if t.kind == "scalar":
            if t.is_primitive:
                ns[f"_v{i}"] = scalar_default(t.base, f.default)
                params.append(f"{a}=_v{i}")
                body.append(f"    self.{a} = {a}")
                continue
            ns[f"_c{i}"] = nested_classes[f.name] = nested(t.base)
            params.append(f"{a}=_D")
            body.append(f"    self.{a} = _c{i}() if {a} is _D else {a}")
            continue
        params.append(f"{a}=_D")
        if t.is_primitive and t.base in DTYPES:
            ns[f"_t{i}"] = DTYPES[t.base]
            if f.default is not None:
                ns[f"_v{i}"] = list(f.default)
                make = f"_np.array(_v{i}, dtype=_t{i})"
            elif t.kind == "array":
                make = f"_np.zeros({t.size}, dtype=_t{i})"
            else:
                make = f"_np.empty(0, dtype=_t{i})"
        elif t.is_primitive:  # strings
            if f.default is not None:
                ns[f"_v{i}"] = list(f.default)
                make = f"list(_v{i})"
            elif t.kind == "array":
                make = f"[''] * {t.size}"
            else:
                make = "[]"
        else:
            ns[f"_c{i}"] = nested_classes[f.name] = nested(t.base)
            make = f"[_c{i}() for _ in range({t.size})]" if t.kind == "array" else "[]"
        body.append(f"    self.{a} = {make} if {a} is _D else {a}")
    if not spec.fields:
        params.append(f"{EMPTY_MEMBER}=0")
        body.append("    pass")
    cls_name = spec.name.split("/")[-1]
    code = f"def __init__(self, {', '.join(params)}):\n" + "\n".join(body) + "\n"
    exec(compile(code, f"<roszen message {spec.name}>", "exec"), ns)  # noqa: S102
    attrs = tuple(attr_name(f.name) for f in spec.fields)
    members: dict[str, object] = {
        "__slots__": attrs,
        "__msgtype__": spec.name,
        "__init__": ns["__init__"],
        "__eq__": _msg_eq,
        "__hash__": None,
        "__repr__": _msg_repr,
        "_spec": spec,
        "_field_types": {attr_name(f.name): f.type.text() for f in spec.fields},
        "_nested_classes": nested_classes,
        "get_fields_and_field_types": classmethod(lambda cls: dict(cls._field_types)),
    }
    if not spec.fields:
        members[EMPTY_MEMBER] = 0
    for c in spec.constants:
        members[c.name] = c.value
    cls = type(cls_name, (), members)
    # fast constructor for the decoder: values in wire-field order, no default handling
    wire = [attr_name(f.name) for f in spec.fields]
    fcode = (f"def _from_values({', '.join(wire) or '_dummy=0'}):\n    o = _new(_cls)\n"
             + "".join(f"    o.{a} = {a}\n" for a in wire) + "    return o\n")
    fns: dict[str, object] = {"_new": object.__new__, "_cls": cls}
    exec(compile(fcode, f"<roszen decoder {spec.name}>", "exec"), fns)  # noqa: S102
    cls._from_values = staticmethod(fns["_from_values"])
    cls.__module__ = f"roszen.msg.{spec.package}"
    cls.__qualname__ = cls_name
    cls.__doc__ = f"ROS 2 message {spec.name}."
    return cls
