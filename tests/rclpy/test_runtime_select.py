"""roszen.runtime: roszen unless ASTROBEE_RUNTIME=rclpy, a bad value one line; on real rclpy
(skipped without it) roszen's parameter descriptors hold: int overrides of doubles coerced,
ranges and choices checked at declare time and on every set, on_change applied, read-only
refused."""
from __future__ import annotations

import importlib.util
import random

import pytest

from roszen import runtime


def test_default_runtime_is_roszen(monkeypatch):
    import roszen
    from roszen import node_main
    monkeypatch.delenv("ASTROBEE_RUNTIME", raising=False)
    assert runtime.name() == "roszen"
    assert runtime.Node is roszen.Node and runtime.node_main is node_main
    assert runtime.message_class("geometry_msgs/msg/Pose") is roszen.message_class("geometry_msgs/msg/Pose")


def test_bad_runtime_is_one_line(monkeypatch):
    monkeypatch.setenv("ASTROBEE_RUNTIME", "ros1")
    with pytest.raises(ValueError, match=r"^ASTROBEE_RUNTIME='ros1': expected one of roszen, rclpy$"):
        runtime.Node  # noqa: B018


def rclpy_installed() -> bool:
    """Real rclpy importable (not this test folder, which pytest can import as a namespace
    package named rclpy)."""
    try:
        return importlib.util.find_spec("rclpy.node") is not None
    except ImportError:
        return False


@pytest.mark.skipif(not rclpy_installed(), reason="real rclpy is not installed here (make install-rclpy)")
def test_parameter_descriptors_on_rclpy(monkeypatch):
    from roszen.parameters import InvalidParameterValueException, Parameter, read_only
    from roszen.parameters import runtime as applied_at_run_time
    monkeypatch.setenv("ASTROBEE_RUNTIME", "rclpy")
    monkeypatch.setenv("ROS_DOMAIN_ID", str(random.randint(101, 200)))
    monkeypatch.setenv("FASTDDS_BUILTIN_TRANSPORTS", "UDPv4")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    import rclpy
    applied: list = []
    node = runtime.Node("param_probe", cli_args=["--ros-args", "-p", "gain:=2", "-p", "mode:=fast"])
    try:
        gain = node.declare_parameter("gain", 1.0, applied_at_run_time(applied.append,
                                                                       min_value=0.0, max_value=5.0))
        assert gain.value == 2.0 and isinstance(gain.value, float)      # YAML 2 for a double
        refused = node.set_parameter(Parameter("gain", value=7.0))
        assert not refused.successful and "<= 5" in refused.reason and applied == []
        assert node.set_parameter(Parameter("gain", value=3.0)).successful and applied == [3.0]
        assert node.get_parameter("gain").value == 3.0
        mode = node.declare_parameter("mode", "slow", read_only(choices=("slow", "fast")))
        assert mode.value == "fast"
        assert not node.set_parameter(Parameter("mode", value="slow")).successful
        with pytest.raises(InvalidParameterValueException, match="limit"):
            node.declare_parameter("limit", 1.0, read_only(max_value=0.5))
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def test_launch_runtime_argument(monkeypatch):
    """runtime:= is the launcher's own: taken out of the description's arguments, checked in
    one line; on rclpy the router goes and the recorder is roszen's on rclpy."""
    from astrobee_bringup import launcher
    from astrobee_bringup.process_group import LaunchError, NodeSpec
    monkeypatch.delenv("ASTROBEE_RUNTIME", raising=False)
    args = {"scenario": "node2_to_jem", "runtime": "roszen"}
    assert launcher.select_runtime(args) == "roszen" and args == {"scenario": "node2_to_jem"}
    with pytest.raises(LaunchError, match=r"^runtime:=ros1: expected roszen \| rclpy$"):
        launcher.select_runtime({"runtime": "ros1"})
    if not rclpy_installed():
        with pytest.raises(LaunchError, match="rclpy is not importable here"):
            launcher.select_runtime({"runtime": "rclpy"})
    specs = [NodeSpec("router", kind="router", command=["router", "--port", "7447"]),
             NodeSpec("sim_node", "astrobee_sim", "sim_node"),
             NodeSpec("recorder", kind="recorder",
                      command=["bag", "record", "-a", "--use-sim-time", "-o", "bag"])]
    out = launcher.rclpy_specs(specs)
    assert [s.name for s in out] == ["sim_node", "recorder"]
    assert out[1].argv[1:] == ["-m", "roszen.rclpy_backend.record", "-a", "--use-sim-time",
                               "-o", "bag"]


def test_verbs_pick_the_runtime_in_one_line(monkeypatch):
    """The verbs' helper node follows ASTROBEE_RUNTIME: a bad value, or rclpy where it is not
    installed, is one line (CliError) before anything joins a graph."""
    from roszen.cli.common import CliError, make_node
    monkeypatch.setenv("ASTROBEE_RUNTIME", "ros1")
    with pytest.raises(CliError, match=r"^ASTROBEE_RUNTIME='ros1': expected one of"):
        make_node()
    if not rclpy_installed():
        monkeypatch.setenv("ASTROBEE_RUNTIME", "rclpy")
        with pytest.raises(CliError, match="rclpy is not importable here"):
            make_node()
