"""roszen's parameter descriptors on a real rclpy node: the descriptor's text and read_only go
to rclpy (so `ros2 param describe` shows them and rclpy refuses a set of a read-only one); the
range, choices, finiteness and validator are checked by roszen's own check_value at declare time
and on every set, and `on_change` applies an accepted set (all or nothing, as on roszen)."""
from __future__ import annotations

from typing import Any, Optional

from ..parameters import (InvalidParameterTypeException, InvalidParameterValueException,
                          Parameter, ParameterDescriptor, ParameterException,
                          ParameterNotDeclaredException, ParameterType, SetParametersResult,
                          check_value, coerce, infer_type)


class RclpyParameters:
    """Mixin of the rclpy-backed Node: `self._rnode` is the rclpy node, `self._descriptors`
    roszen's descriptors by name."""

    _rnode: Any
    _descriptors: dict

    def _install_parameter_callback(self) -> None:
        self._rnode.add_on_set_parameters_callback(self._on_set)

    def declare_parameter(self, name: str, value: Any = None,
                          descriptor: Optional[ParameterDescriptor] = None,
                          ignore_override: bool = False) -> Parameter:
        """Declare on the rclpy node; an override of a compatible type (YAML `7` for a double)
        is coerced first; a value outside the descriptor's checks raises (one line)."""
        from rcl_interfaces.msg import ParameterDescriptor as RclDescriptor
        from rclpy.exceptions import (InvalidParameterTypeException as RclTypeError,
                                      InvalidParameterValueException as RclValueError)
        from rclpy.parameter import Parameter as RclParameter
        desc = descriptor or ParameterDescriptor()
        desc.name = name
        if isinstance(value, ParameterType):
            value = None
        ptype = infer_type(value)
        overrides = self._rnode._parameter_overrides          # rclpy: name -> Parameter
        if not ignore_override and name in overrides and ptype != ParameterType.NOT_SET \
                and not desc.dynamic_typing:
            try:
                v = coerce(overrides[name].value, ptype)
            except InvalidParameterTypeException as e:
                raise InvalidParameterTypeException(
                    f"parameter {name!r} override has the wrong type: {e}") from None
            overrides[name] = RclParameter(name, value=v)
        # the descriptor is ours until declared, so the set callback checks the start value too
        self._descriptors[name] = desc
        rdesc = RclDescriptor(name=name, description=desc.description,
                              additional_constraints=desc.additional_constraints,
                              read_only=desc.read_only,
                              # no default: roszen takes the override's type, rclpy needs this
                              dynamic_typing=desc.dynamic_typing or value is None)
        try:
            p = self._rnode.declare_parameter(name, value, rdesc, ignore_override)
        except (RclTypeError, RclValueError) as exc:
            self._descriptors.pop(name, None)
            raise InvalidParameterValueException(f"parameter {name!r}: {exc}") from None
        out = Parameter(name, value=p.value)
        try:
            check_value(out, desc)
        except ParameterException:
            self._descriptors.pop(name, None)
            raise
        return out

    def has_parameter(self, name: str) -> bool:
        return self._rnode.has_parameter(name)

    def get_parameter(self, name: str) -> Parameter:
        if not self._rnode.has_parameter(name):
            raise ParameterNotDeclaredException(name)
        return Parameter(name, value=self._rnode.get_parameter(name).value)

    def get_parameters_by_prefix(self, prefix: str) -> dict:
        return {k: Parameter(p.name, value=p.value)
                for k, p in self._rnode.get_parameters_by_prefix(prefix).items()}

    def describe_parameter(self, name: str) -> ParameterDescriptor:
        if name not in self._descriptors:
            raise ParameterNotDeclaredException(name)
        return self._descriptors[name]

    def set_parameters_atomically(self, parameters: list) -> SetParametersResult:
        from rclpy.parameter import Parameter as RclParameter
        r = self._rnode.set_parameters_atomically(
            [RclParameter(p.name, value=p.value) for p in parameters])
        return SetParametersResult(r.successful, r.reason)

    def set_parameter(self, parameter: Parameter) -> SetParametersResult:
        return self.set_parameters_atomically([parameter])

    def set_parameters(self, parameters: list) -> list:
        return [self.set_parameters_atomically([p]) for p in parameters]

    def _on_set(self, params: list) -> Any:
        """rclpy's set callback: roszen's checks, then each on_change; a refusal undoes the
        values already applied and fails the whole set."""
        from rcl_interfaces.msg import SetParametersResult as RclResult
        checked = []
        try:
            for rp in params:
                desc = self._descriptors.get(rp.name)
                p = Parameter(rp.name, value=rp.value)
                if desc is None:
                    continue
                cur = self._rnode.get_parameter(rp.name) if self._rnode.has_parameter(rp.name) \
                    else None
                if cur is not None and cur.value is not None and not desc.dynamic_typing:
                    p = Parameter(rp.name, value=coerce(rp.value, infer_type(cur.value)))
                check_value(p, desc)
                checked.append((p, desc))
        except (ParameterException, ValueError, TypeError) as e:
            return RclResult(successful=False, reason=str(e))
        applied: list = []
        for p, desc in checked:
            if desc.on_change is None or p.type_ == ParameterType.NOT_SET or \
                    not self._rnode.has_parameter(p.name):
                continue            # (the start value: read by the node itself)
            try:
                desc.on_change(p.value)
            except Exception as e:  # noqa: BLE001 - a failing apply must not kill the node
                for name, undo in reversed(applied):
                    try:
                        undo(self._rnode.get_parameter(name).value)
                    except Exception as e2:  # noqa: BLE001
                        self.get_logger().error(f"parameter {name!r}: restoring failed: {e2}")
                return RclResult(successful=False, reason=f"parameter {p.name!r} not applied: {e}")
            applied.append((p.name, desc.on_change))
        return RclResult(successful=True, reason="")
