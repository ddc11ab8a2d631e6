"""Descriptors with ranges and choices, read-only ones too, checked on every path; sets all-or-nothing."""
from __future__ import annotations

import pytest

import roszen
from roszen.parameters import InvalidParameterValueException, read_only, runtime


def _node(name: str, *overrides: str) -> roszen.Node:
    argv = ["--ros-args", *[a for o in overrides for a in ("-p", o)]] if overrides else None
    return roszen.Node(name, argv=argv, use_global_arguments=False, start_parameter_services=False,
                       enable_rosout=False)


def test_read_only_range_and_choices_are_checked_at_start(router_env):
    node = _node("ro_checks", "mass:=1.0e+300", "mode:=warp")
    try:
        with pytest.raises(InvalidParameterValueException, match="<= 100"):
            node.declare_parameter("mass", 1.0, read_only(min_value=0.05, max_value=100.0))
        with pytest.raises(InvalidParameterValueException, match="one of nominal, quiet"):
            node.declare_parameter("mode", "nominal", read_only(choices=("nominal", "quiet")))
        d = node.declare_parameter("size", [0.5, 0.5], read_only(min_value=0.01, max_value=2.0))
        assert d.value == [0.5, 0.5]
        assert "one of a, b" in read_only(choices=("a", "b")).additional_constraints
    finally:
        node.destroy_node()


def test_array_elements_are_each_within_the_range(router_env):
    node = _node("arr_checks", "size:=[1000.0, 1000.0, 1000.0]")
    try:
        with pytest.raises(InvalidParameterValueException, match="<= 2"):
            node.declare_parameter("size", [0.5, 0.5, 0.5], read_only(min_value=0.01, max_value=2.0))
    finally:
        node.destroy_node()


def test_runtime_choices_refuse_unknown_and_empty(router_env):
    node = _node("choice_checks")
    seen = []
    try:
        node.declare_parameter("mode", "nominal", runtime(seen.append, choices=("nominal", "quiet")))
        for bad in ("", "x" * 5000, "warp"):
            r = node.set_parameter(roszen.Parameter("mode", value=bad))
            assert not r.successful and len(r.reason) < 200, r.reason
        assert node.get_parameter("mode").value == "nominal" and seen == []
        assert node.set_parameter(roszen.Parameter("mode", value="quiet")).successful
        assert node.get_parameter("mode").value == "quiet" and seen == ["quiet"]
    finally:
        node.destroy_node()


def test_set_atomically_is_all_or_nothing(router_env):
    node = _node("atomic_checks")
    applied: dict = {}

    def apply_y(v: float) -> None:
        if v > 3.0:
            raise ValueError("too fast for this node")
        applied["y"] = v

    try:
        node.declare_parameter("x", 1.0, runtime(lambda v: applied.__setitem__("x", v)))
        node.declare_parameter("y", 1.0, runtime(apply_y))
        r = node.set_parameters_atomically([roszen.Parameter("x", value=2.0),
                                            roszen.Parameter("y", value=5.0)])
        assert not r.successful and "too fast" in r.reason
        assert node.get_parameter("x").value == 1.0 and applied["x"] == 1.0  # rolled back
        r = node.set_parameters_atomically([roszen.Parameter("x", value=2.0),
                                            roszen.Parameter("y", value=-1.0e400)])
        assert not r.successful and applied == {"x": 1.0}                    # refused before any apply
        assert node.set_parameters_atomically([roszen.Parameter("x", value=2.0),
                                               roszen.Parameter("y", value=3.0)]).successful
        assert applied == {"x": 2.0, "y": 3.0}
    finally:
        node.destroy_node()
