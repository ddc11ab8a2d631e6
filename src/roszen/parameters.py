"""Typed node parameters (rclpy-like) with descriptors and set-time validation."""
from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any, Optional


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
    """Mirror of rcl_interfaces/msg/ParameterDescriptor (ranges not enforced beyond min/max)."""
    name: str = ""
    type: int = 0
    description: str = ""
    additional_constraints: str = ""
    read_only: bool = False
    dynamic_typing: bool = False
    min_value: Optional[float] = None
    max_value: Optional[float] = None


@dataclass
class SetParametersResult:
    successful: bool = True
    reason: str = ""
