"""Parameters from YAML files and --ros-args, served over the rcl_interfaces services."""
from __future__ import annotations

import os
import textwrap

import pytest

import roszen
from roszen.args import RosArgsError, load_params_file, parse_args
from roszen.param_services import ParameterClient
from roszen.parameters import InvalidParameterTypeException, ParameterDescriptor, ParameterNotDeclaredException
from roszen.testing import python_cmd, read_until, spawn, stop

PEER = os.path.join(os.path.dirname(__file__), "peer.py")


def test_parse_ros_args():
    user, ros = parse_args(["prog", "x", "--ros-args", "-p", "rate:=2", "-p", "gains:=[1, 2.5]",
                            "-r", "__ns:=/robot", "-r", "chatter:=talk", "--params-file", "f.yaml", "--", "y"])
    assert user == ["prog", "x", "y"]
    assert ros.params == [(None, "rate", 2), (None, "gains", [1, 2.5])]
    assert ros.namespace == "/robot" and ros.params_files == ["f.yaml"]
    assert ros.remaps == [(None, "chatter", "talk")]
    with pytest.raises(RosArgsError):
        parse_args(["--ros-args", "-p", "novalue"])
    with pytest.raises(RosArgsError):
        parse_args(["--ros-args", "--bogus"])


def test_params_file_matching(tmp_path):
    f = tmp_path / "p.yaml"
    f.write_text(textwrap.dedent("""
        /**:
          ros__parameters:
            common: 1
            rate: 5.0
        sim_node:
          ros__parameters:
            rate: 350.0
            nested: {a: 1, b: [1.0, 2.0]}
        other:
          ros__parameters:
            rate: 1.0
        /robot/ctl:
          ros__parameters:
            gain: 3
    """))
    assert load_params_file(str(f), "sim_node", "/") == {"common": 1, "rate": 350.0, "nested.a": 1,
                                                        "nested.b": [1.0, 2.0]}
    assert load_params_file(str(f), "ctl", "/robot") == {"common": 1, "rate": 5.0, "gain": 3}
    bad = tmp_path / "bad.yaml"
    bad.write_text("- a list\n")
    with pytest.raises(RosArgsError):
        load_params_file(str(bad), "x", "/")


def test_declare_types_and_overrides(router_env, tmp_path):
    f = tmp_path / "p.yaml"
    f.write_text("n1:\n  ros__parameters:\n    rate: 7\n    label: from_file\n")
    node = roszen.Node("n1", argv=["--ros-args", "--params-file", str(f), "-p", "label:=from_cli"],
                       use_global_arguments=False, start_parameter_services=False)
    try:
        assert node.declare_parameter("rate", 1.0).value == 7.0          # int in YAML -> double param
        assert isinstance(node.get_parameter("rate").value, float)
        assert node.declare_parameter("label", "x").value == "from_cli"  # -p wins over the file
        node.declare_parameter("fixed", 3, ParameterDescriptor(read_only=True))
        assert not node.set_parameter(roszen.Parameter("fixed", value=4)).successful
        assert not node.set_parameter(roszen.Parameter("rate", value="fast")).successful
        assert node.set_parameter(roszen.Parameter("rate", value=2.5)).successful
        assert node.get_parameter("rate").value == 2.5
        with pytest.raises(ParameterNotDeclaredException):
            node.get_parameter("nope")
        with pytest.raises(InvalidParameterTypeException):
            roszen.Node("n1", argv=["--ros-args", "-p", "rate:=abc"], use_global_arguments=False,
                        start_parameter_services=False, enable_rosout=False).declare_parameter("rate", 1.0)
    finally:
        node.destroy_node()


@pytest.mark.graph
def test_params_and_names_in_a_process(router_env, tmp_path):
    f = tmp_path / "p.yaml"
    f.write_text("/**:\n  ros__parameters:\n    rate: 50.0\n    gains: [1.0, 2.0]\n")
    p = spawn(python_cmd(PEER, "params", "--ros-args", "--params-file", str(f), "-p", "name:=abc",
                         "-p", "enabled:=true", "-r", "__ns:=/robot", "-r", "__node:=ctl", "-r", "chatter:=/talk"),
              router_env)
    try:
        lines = read_until(p, "DONE", timeout=15)
    finally:
        stop(p)
    assert "PARAM rate 50.0" in lines
    assert "PARAM name 'abc'" in lines
    assert "PARAM gains [1.0, 2.0]" in lines
    assert "PARAM enabled True" in lines
    assert "NAME /robot/ctl /talk /robot/ctl/private" in lines


@pytest.mark.graph
def test_parameter_services_remote(router_env):
    server = roszen.Context()
    client = roszen.Context()
    a = roszen.Node("param_owner", context=server)
    b = roszen.Node("param_user", context=client)
    import threading
    stop_ev = threading.Event()
    th = threading.Thread(target=lambda: [a.spin_once(0.05) for _ in iter(lambda: stop_ev.is_set(), True)])
    th.start()
    try:
        a.declare_parameter("speed", 1.5)
        a.declare_parameter("mode", "auto", ParameterDescriptor(read_only=True))
        pc = ParameterClient(b, "/param_owner")
        assert pc.wait(10.0)
        assert pc.get(["speed", "mode", "missing"]) == [1.5, "auto", None]
        assert set(pc.list()) >= {"speed", "mode", "use_sim_time"}
        assert pc.set({"speed": 3.0}) == [(True, "")]
        ok, reason = pc.set({"mode": "manual"})[0]
        assert not ok and "read-only" in reason
        assert a.get_parameter("speed").value == 3.0
        (d,) = pc.describe(["mode"])
        assert d.read_only and d.type == 4
    finally:
        stop_ev.set()
        th.join(5)
        server.shutdown()
        client.shutdown()
