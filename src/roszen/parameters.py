"""Typed node parameters (rclpy-like) with descriptors and set-time validation.

Beyond rcl_interfaces' descriptor (read_only, ranges), a roszen descriptor may carry a
`validator` (raises ValueError for a value the node cannot take) and an `on_change` callback
(applies a new value while the node runs). A node states for each parameter either that it is
read-only (`read_only()`: read once at start; `param set` is refused with "parameter 'X' is
read-only", as in ROS 2) or how it is applied at run time (`runtime(apply, ...)`): a writable
parameter with neither would report success and change nothing.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Optional, Sequence


class ParameterType(enum.IntEnum):
    """rcl_interfaces/msg/ParameterType values."""
    NOT_SET = 0
    BOOL = 1
    INTEGER = 2
    DOUBLE = 3
    STRING = 4
    BYTE_ARRAY = 5
    BOOL_ARRAY = 6
    INTEGER_ARRAY = 7
    DOUBLE_ARRAY = 8
    STRING_ARRAY = 9


class ParameterException(Exception):
    """Base class of parameter errors."""


class ParameterNotDeclaredException(ParameterException, KeyError):
    def __str__(self) -> str:
        return f"parameter {self.args[0]!r} is not declared"


class ParameterAlreadyDeclaredException(ParameterException):
    pass


class InvalidParameterTypeException(ParameterException, TypeError):
    pass


class InvalidParameterValueException(ParameterException, ValueError):
    pass


class ParameterImmutableException(ParameterException):
    pass


def infer_type(value: Any) -> ParameterType:
    """The ParameterType of a Python value (ValueError if it has none)."""
    import numpy as np
    if value is None:
        return ParameterType.NOT_SET
    if isinstance(value, (bool, np.bool_)):
        return ParameterType.BOOL
    if isinstance(value, (int, np.integer)):
        return ParameterType.INTEGER
    if isinstance(value, (float, np.floating)):
        return ParameterType.DOUBLE
    if isinstance(value, str):
        return ParameterType.STRING
    if isinstance(value, (bytes, bytearray)):
        return ParameterType.BYTE_ARRAY
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        if not value:
            return ParameterType.STRING_ARRAY  # rclpy cannot tell either; any array type accepts []
        if all(isinstance(v, (bool, np.bool_)) for v in value):
            return ParameterType.BOOL_ARRAY
        if all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in value):
            return ParameterType.INTEGER_ARRAY
        if all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) for v in value):
            return ParameterType.DOUBLE_ARRAY
        if all(isinstance(v, str) for v in value):
            return ParameterType.STRING_ARRAY
    raise InvalidParameterValueException(f"unsupported parameter value {value!r}")


def coerce(value: Any, ptype: ParameterType) -> Any:
    """Convert a value to ptype where that is lossless (int -> double, lists); else raise."""
    import numpy as np
    vtype = infer_type(value)
    if vtype == ptype:
        if ptype == ParameterType.DOUBLE_ARRAY:
            return [float(v) for v in (value.tolist() if isinstance(value, np.ndarray) else value)]
        if isinstance(value, np.ndarray):
            return value.tolist()
        if ptype == ParameterType.DOUBLE:
            return float(value)
        if ptype == ParameterType.INTEGER:
            return int(value)
        if ptype == ParameterType.BOOL:
            return bool(value)
        return list(value) if isinstance(value, tuple) else value
    if ptype == ParameterType.DOUBLE and vtype == ParameterType.INTEGER:
        return float(value)
    if ptype == ParameterType.DOUBLE_ARRAY and vtype == ParameterType.INTEGER_ARRAY:
        return [float(v) for v in value]
    if ptype in (ParameterType.BOOL_ARRAY, ParameterType.INTEGER_ARRAY, ParameterType.DOUBLE_ARRAY,
                 ParameterType.STRING_ARRAY) and isinstance(value, (list, tuple)) and not value:
        return []
    raise InvalidParameterTypeException(
        f"expected {ptype.name.lower()}, got {vtype.name.lower()} value {value!r}")


class Parameter:
    """A named, typed value (`.value`, `.type_`, `.name`)."""
    Type = ParameterType

    def __init__(self, name: str, type_: Optional[ParameterType] = None, value: Any = None) -> None:
        if type_ is not None and not isinstance(type_, ParameterType) and value is None:
            type_, value = None, type_  # Parameter(name, value) convenience
        self.name = name
        if type_ is None:
            type_ = infer_type(value)
        self.type_ = ParameterType(type_)
        self.value = None if self.type_ == ParameterType.NOT_SET else coerce(value, self.type_)

    def __repr__(self) -> str:
        return f"Parameter({self.name!r}, {self.type_.name}, {self.value!r})"

    def get_parameter_value(self) -> Any:
        return self.value


@dataclass
class ParameterDescriptor:
    """Mirror of rcl_interfaces/msg/ParameterDescriptor (a range is min_value..max_value,
    inclusive; a non-finite value is outside every range), plus roszen-only fields that never
    go on the wire (additional_constraints says them in words): `choices` (the values allowed;
    for an array, each element), `validator(value)` raises ValueError for a value the node
    refuses, `on_change(value)` applies an accepted new value at run time (it may raise
    ValueError too: the set then fails and the old value stays)."""
    name: str = ""
    type: int = 0
    description: str = ""
    additional_constraints: str = ""
    read_only: bool = False
    dynamic_typing: bool = False
    min_value: Optional[float] = None
    max_value: Optional[float] = None
    choices: Optional[tuple] = None
    validator: Optional[Callable[[Any], None]] = field(default=None, repr=False, compare=False)
    on_change: Optional[Callable[[Any], None]] = field(default=None, repr=False, compare=False)


def _constraints(min_value: Optional[float], max_value: Optional[float],
                 choices: Optional[Sequence[Any]], when: str, finite: bool = False) -> str:
    """The additional_constraints text a descriptor shows in `param describe`."""
    words = []
    if finite or min_value is not None or max_value is not None:
        words.append("finite")
    if min_value is not None:
        words.append(f">= {min_value:g}")
    if max_value is not None:
        words.append(f"<= {max_value:g}")
    if choices is not None:
        words.append("one of " + ", ".join(map(str, choices)))
    return " and ".join(words) + ("; " if words else "") + when


def read_only(description: str = "", *, min_value: Optional[float] = None,
              max_value: Optional[float] = None, choices: Optional[Sequence[Any]] = None,
              validator: Optional[Callable[[Any], None]] = None) -> ParameterDescriptor:
    """A parameter read once at start (`param set` is refused); its start value (default,
    YAML or --ros-args) must be within [min_value, max_value], one of `choices` and accepted
    by `validator`, or the node refuses to start."""
    return ParameterDescriptor(description=description, read_only=True, min_value=min_value,
                               max_value=max_value, validator=validator,
                               choices=None if choices is None else tuple(choices),
                               additional_constraints=_constraints(min_value, max_value, choices,
                                                                   "read-only: read at start"))


def runtime(apply: Callable[[Any], None], description: str = "", *,
            min_value: Optional[float] = None, max_value: Optional[float] = None,
            choices: Optional[Sequence[Any]] = None,
            validator: Optional[Callable[[Any], None]] = None) -> ParameterDescriptor:
    """A parameter applied at run time by `apply(value)`; numbers must be finite and, when
    given, within [min_value, max_value] and one of `choices`; `validator` refuses other bad
    values. The same checks hold for the start value."""
    text = _constraints(min_value, max_value, choices, "applied at run time", finite=choices is None)
    return ParameterDescriptor(description=description, min_value=min_value, max_value=max_value,
                               choices=None if choices is None else tuple(choices),
                               validator=validator, on_change=apply, additional_constraints=text)


def _non_finite(value: Any) -> bool:
    vals = value if isinstance(value, (list, tuple)) else [value]
    return any(isinstance(v, float) and not math.isfinite(v) for v in vals)


def check_value(p: "Parameter", desc: ParameterDescriptor) -> None:
    """InvalidParameterValueException unless p's value is within the descriptor's range, finite
    where the descriptor has a range or applies values at run time, one of its choices and
    accepted by its validator (any exception a validator raises is a refusal)."""
    if p.type_ == ParameterType.NOT_SET:
        return
    if (desc.on_change is not None or desc.min_value is not None or desc.max_value is not None) \
            and _non_finite(p.value):
        raise InvalidParameterValueException(f"parameter {p.name!r} must be finite, got {p.value!r}")
    vals = p.value if isinstance(p.value, list) else [p.value]
    numeric = p.type_ in (ParameterType.INTEGER, ParameterType.DOUBLE, ParameterType.INTEGER_ARRAY,
                          ParameterType.DOUBLE_ARRAY)
    for v in vals if numeric else ():
        if desc.min_value is not None and v < desc.min_value:
            raise InvalidParameterValueException(
                f"parameter {p.name!r} must be >= {desc.min_value:g}, got {_short(p.value)}")
        if desc.max_value is not None and v > desc.max_value:
            raise InvalidParameterValueException(
                f"parameter {p.name!r} must be <= {desc.max_value:g}, got {_short(p.value)}")
    if desc.choices is not None and any(v not in desc.choices for v in vals):
        raise InvalidParameterValueException(
            f"parameter {p.name!r} must be one of {', '.join(map(str, desc.choices))}; "
            f"got {_short(p.value)}")
    if desc.validator is not None:
        try:
            desc.validator(p.value)
        except Exception as exc:    # noqa: BLE001 - whatever a validator raises is a refusal
            raise InvalidParameterValueException(f"parameter {p.name!r}: {_short(exc)}") from None


def _short(x: Any, limit: int = 80) -> str:
    """repr/str of x cut to `limit` characters (a flood of 'xxx...' must not flood the log)."""
    s = str(x) if isinstance(x, BaseException) else repr(x)
    return s if len(s) <= limit else s[:limit - 3] + "..."


@dataclass
class SetParametersResult:
    successful: bool = True
    reason: str = ""
