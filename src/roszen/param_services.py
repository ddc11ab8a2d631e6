"""The rcl_interfaces parameter services (~/get_parameters ...) so `ros2 param` works on our nodes."""
from __future__ import annotations

from typing import Any

import numpy as np

from . import codec
from .parameters import Parameter, ParameterType

_SRV = "rcl_interfaces/srv/"
_FIELDS = {
    ParameterType.BOOL: "bool_value", ParameterType.INTEGER: "integer_value",
    ParameterType.DOUBLE: "double_value", ParameterType.STRING: "string_value",
    ParameterType.BYTE_ARRAY: "byte_array_value", ParameterType.BOOL_ARRAY: "bool_array_value",
    ParameterType.INTEGER_ARRAY: "integer_array_value", ParameterType.DOUBLE_ARRAY: "double_array_value",
    ParameterType.STRING_ARRAY: "string_array_value",
}


def to_value_msg(cls: type, p: Parameter) -> Any:
    """Parameter -> rcl_interfaces/msg/ParameterValue."""
    m = cls()
    m.type = int(p.type_)
    field = _FIELDS.get(p.type_)
    if field is not None:
        v = p.value
        if p.type_ == ParameterType.BYTE_ARRAY:
            v = np.frombuffer(bytes(v), dtype=np.uint8).copy()
        elif p.type_ in (ParameterType.BOOL_ARRAY, ParameterType.INTEGER_ARRAY, ParameterType.DOUBLE_ARRAY):
            v = np.asarray(v, dtype=getattr(m, field).dtype)
        setattr(m, field, v)
    return m


def from_value_msg(name: str, m: Any) -> Parameter:
    """rcl_interfaces/msg/ParameterValue -> Parameter (NOT_SET deletes on set)."""
    t = ParameterType(int(m.type))
    if t == ParameterType.NOT_SET:
        return Parameter(name, ParameterType.NOT_SET, None)
    v = getattr(m, _FIELDS[t])
    if t == ParameterType.BYTE_ARRAY:
        v = bytes(np.asarray(v, dtype=np.uint8))
    elif isinstance(v, np.ndarray):
        v = v.tolist()
    return Parameter(name, t, list(v) if t == ParameterType.STRING_ARRAY else v)


class ParameterServices:
    """Serves get/set/list/describe/get_types/set_atomically under the node's private namespace."""

    def __init__(self, node) -> None:
        self.node = node
        for t in ("GetParameters", "SetParameters", "ListParameters", "DescribeParameters",
                  "GetParameterTypes", "SetParametersAtomically"):
            codec.srv_support(_SRV + t)  # TypeSupportError if the typestore lacks them
        from . import typestore
        self._Value = typestore.message_class("rcl_interfaces/msg/ParameterValue")
        self._Result = typestore.message_class("rcl_interfaces/msg/SetParametersResult")
        self._Desc = typestore.message_class("rcl_interfaces/msg/ParameterDescriptor")
        self._FRange = typestore.message_class("rcl_interfaces/msg/FloatingPointRange")
        self._IRange = typestore.message_class("rcl_interfaces/msg/IntegerRange")
        self._resp = {t: codec.srv_support(_SRV + t).response.cls for t in
                      ("GetParameters", "SetParameters", "ListParameters", "DescribeParameters",
                       "GetParameterTypes", "SetParametersAtomically")}
        node.create_service(_SRV + "GetParameters", "~/get_parameters", self._get)
        node.create_service(_SRV + "SetParameters", "~/set_parameters", self._set)
        node.create_service(_SRV + "SetParametersAtomically", "~/set_parameters_atomically", self._set_atomic)
        node.create_service(_SRV + "ListParameters", "~/list_parameters", self._list)
        node.create_service(_SRV + "DescribeParameters", "~/describe_parameters", self._describe)
        node.create_service(_SRV + "GetParameterTypes", "~/get_parameter_types", self._types)

    def _get(self, req):
        r = self._resp["GetParameters"]()
        r.values = [to_value_msg(self._Value, self.node.get_parameter_or(n)) for n in req.names]
        return r

    def _result(self, res):
        m = self._Result()
        m.successful, m.reason = bool(res.successful), res.reason
        return m

    def _params(self, msgs) -> list:
        return [from_value_msg(p.name, p.value) for p in msgs]

    def _set(self, req):
        r = self._resp["SetParameters"]()
        out = []
        for p in req.parameters:
            try:
                res = self.node.set_parameters_atomically(self._params([p]))
            except Exception as e:  # a bad value must not kill the node
                from .parameters import SetParametersResult
                res = SetParametersResult(False, str(e))
            out.append(self._result(res))
        r.results = out
        return r

    def _set_atomic(self, req):
        r = self._resp["SetParametersAtomically"]()
        try:
            res = self.node.set_parameters_atomically(self._params(req.parameters))
        except Exception as e:
            from .parameters import SetParametersResult
            res = SetParametersResult(False, str(e))
        r.result = self._result(res)
        return r

    def _list(self, req):
        r = self._resp["ListParameters"]()
        names, prefixes = [], set()
        depth = int(req.depth)
        for name in sorted(self.node._params):
            if req.prefixes and not any(name == p or name.startswith(p + ".") for p in req.prefixes):
                continue
            if depth and name.count(".") >= depth:
                continue
            names.append(name)
            if "." in name:
                prefixes.add(name.rsplit(".", 1)[0])
        r.result.names = names
        r.result.prefixes = sorted(prefixes)
        return r

    def _describe(self, req):
        r = self._resp["DescribeParameters"]()
        out = []
        for n in req.names:
            d = self._Desc()
            d.name = n
            desc = self.node._descriptors.get(n)
            if desc is not None:
                d.type = int(self.node._params[n].type_)
                d.description = desc.description
                d.additional_constraints = desc.additional_constraints
                d.read_only = bool(desc.read_only)
                d.dynamic_typing = bool(desc.dynamic_typing)
                if desc.min_value is not None or desc.max_value is not None:
                    if d.type == ParameterType.INTEGER:
                        rng = self._IRange()
                        rng.from_value = int(desc.min_value if desc.min_value is not None else -2**63)
                        rng.to_value = int(desc.max_value if desc.max_value is not None else 2**63 - 1)
                        d.integer_range = [rng]
                    else:
                        rng = self._FRange()
                        rng.from_value = float(desc.min_value if desc.min_value is not None else -float("inf"))
                        rng.to_value = float(desc.max_value if desc.max_value is not None else float("inf"))
                        d.floating_point_range = [rng]
            out.append(d)
        r.descriptors = out
        return r

    def _types(self, req):
        r = self._resp["GetParameterTypes"]()
        r.types = np.array([int(self.node.get_parameter_or(n).type_) for n in req.names], dtype=np.uint8)
        return r


class ParameterClient:
    """Calls another node's parameter services (what `ros2 param get/set/list` does)."""

    def __init__(self, node, remote_node: str) -> None:
        self.node = node
        base = remote_node if remote_node.startswith("/") else "/" + remote_node
        from . import typestore
        self._Value = typestore.message_class("rcl_interfaces/msg/ParameterValue")
        self._Param = typestore.message_class("rcl_interfaces/msg/Parameter")
        self._cli = {t: node.create_client(_SRV + t, f"{base}/{s}") for t, s in (
            ("GetParameters", "get_parameters"), ("SetParameters", "set_parameters"),
            ("ListParameters", "list_parameters"), ("DescribeParameters", "describe_parameters"))}

    def wait(self, timeout_sec: float = 5.0) -> bool:
        return all(c.wait_for_service(timeout_sec) for c in self._cli.values())

    def _call(self, t: str, fill, timeout_sec: float):
        cli = self._cli[t]
        req = cli._sup.request.cls()
        fill(req)
        return cli.call(req, timeout_sec=timeout_sec)

    def get(self, names: list, timeout_sec: float = 5.0) -> list:
        """Values (Python) of the remote parameters; None for undeclared ones."""
        r = self._call("GetParameters", lambda q: setattr(q, "names", list(names)), timeout_sec)
        return [from_value_msg(n, v).value for n, v in zip(names, r.values)]

    def set(self, values: dict, timeout_sec: float = 5.0) -> list:
        """[(successful, reason)] for each name=value."""
        msgs = []
        for k, v in values.items():
            m = self._Param()
            m.name = k
            m.value = to_value_msg(self._Value, Parameter(k, value=v))
            msgs.append(m)
        r = self._call("SetParameters", lambda q: setattr(q, "parameters", msgs), timeout_sec)
        return [(bool(x.successful), x.reason) for x in r.results]

    def list(self, timeout_sec: float = 5.0) -> list:
        return list(self._call("ListParameters", lambda q: None, timeout_sec).result.names)

    def describe(self, names: list, timeout_sec: float = 5.0) -> list:
        return list(self._call("DescribeParameters", lambda q: setattr(q, "names", list(names)),
                               timeout_sec).descriptors)

    def destroy(self) -> None:
        for c in self._cli.values():
            self.node.destroy_client(c)
