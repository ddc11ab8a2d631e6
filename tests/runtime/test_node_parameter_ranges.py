"""The controller's and the safety filter's run-time parameters keep sim_node's ranges: a bag of
1e300 kg or 1 km, an unknown or empty flight mode are refused, at start and by `param set`."""
from __future__ import annotations

import pytest

import roszen
from astrobee_control import registry
from astrobee_control.controller_node import ControllerNode
from astrobee_control.safety_filter_node import SafetyFilterNode
from roszen.parameters import InvalidParameterValueException

BAD = [("bag_mass", 1.0e300), ("bag_mass", 1000.0), ("bag_mass", 0.01), ("bag_mass", float("nan")),
       ("bag_size", [1000.0, 1000.0, 1000.0]), ("bag_size", [0.5, -0.4, 0.3]),
       ("bag_size", [0.5, 0.4]), ("flight_mode", ""), ("flight_mode", "x" * 300),
       ("flight_mode", "warp")]
GOOD = [("bag_mass", 5.0), ("bag_mass", -1.0), ("bag_size", [0.5, 0.42, 0.25]),
        ("bag_size", [0.0, 0.0, 0.0]), ("flight_mode", "quiet")]


def _controller(argv=None) -> ControllerNode:
    law = registry.get("pd")
    return ControllerNode(law.make_law, "range_ctl", dict(law.params()), argv=argv)


@pytest.mark.parametrize("make", [_controller, lambda: SafetyFilterNode()], ids=["controller", "safety"])
def test_param_set_keeps_the_ranges(router_env, make):
    node = make()
    try:
        n = node.node
        for name, value in BAD:
            before = n.get_parameter(name).value
            r = n.set_parameter(roszen.Parameter(name, value=value))
            assert not r.successful and name in r.reason and len(r.reason) < 200, (name, value)
            assert n.get_parameter(name).value == before
        for name, value in GOOD:
            assert n.set_parameter(roszen.Parameter(name, value=value)).successful, (name, value)
        assert node.bag.mass_param == -1.0 and node.bag.size_param is None
        assert n.get_parameter("flight_mode").value == "quiet"
        assert "<= 100" in n.describe_parameter("bag_mass").additional_constraints
        assert "one of off, nominal" in n.describe_parameter("flight_mode").additional_constraints
    finally:
        node.node.destroy_node()


@pytest.mark.parametrize("override", ["bag_mass:=1.0e+300", "bag_size:=[1000.0, 1000.0, 1000.0]",
                                      "flight_mode:=warp", "state_source:=gps"])
def test_a_bad_start_value_is_refused(router_env, override):
    with pytest.raises(InvalidParameterValueException, match=override.split(":=")[0]):
        _controller(["--ros-args", "-p", override])
