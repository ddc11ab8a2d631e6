"""A flood of malformed parameter-service requests never applies a value the descriptor refuses."""
from __future__ import annotations

import random

import roszen
from roszen import codec
from roszen.param_services import to_value_msg
from roszen.parameters import runtime

MODES = ("nominal", "difficult", "quiet", "precision", "off")


def _request(svc: str) -> tuple:
    """(support, serialised request) of a set naming flight_mode with five bad values."""
    sup = codec.srv_support("rcl_interfaces/srv/" + svc)
    P = roszen.message_class("rcl_interfaces/msg/Parameter")
    V = roszen.message_class("rcl_interfaces/msg/ParameterValue")
    params = []
    for val in ("x" * 40, "", 5, ["x" * 10], b"xx"):
        p = P()
        p.name = "flight_mode"
        p.value = to_value_msg(V, roszen.Parameter("flight_mode", value=val))
        params.append(p)
    req = sup.request.cls()
    req.parameters = params
    return sup, bytes(sup.request.serialize(req))


def test_mutated_set_requests_never_apply_a_refused_value(router_env):
    node = roszen.Node("fuzzed", use_global_arguments=False, enable_rosout=False)
    applied: list = []
    try:
        node.declare_parameter("flight_mode", "nominal", runtime(applied.append, choices=MODES))
        services = node._param_services
        rnd = random.Random(7)
        decoded = 0
        for svc, handler in (("SetParameters", services._set),
                             ("SetParametersAtomically", services._set_atomic)):
            sup, data = _request(svc)
            for _ in range(3000):
                d = bytearray(data)
                for _ in range(rnd.randint(1, 12)):
                    d[rnd.randrange(len(d))] = rnd.randrange(256)
                try:
                    req = sup.request.deserialize(bytes(d))
                except Exception:  # noqa: BLE001 - the service refuses these before any handler
                    continue
                decoded += 1
                handler(req)
                assert node.get_parameter("flight_mode").value in MODES, \
                    repr(node.get_parameter("flight_mode").value)[:80]
        assert decoded > 200 and all(m in MODES for m in applied)
    finally:
        node.destroy_node()
