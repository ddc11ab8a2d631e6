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


def test_runtime_and_read_only_descriptors(router_env):
    """A runtime parameter is applied on set (its callback sees the value); a bad value is
    refused with a reason and changes nothing; a read-only one is refused as ROS 2 does."""
    from roszen.parameters import read_only, runtime
    node = roszen.Node("n2", argv=["--ros-args", "-p", "rate:=4.0"], use_global_arguments=False,
                       start_parameter_services=False, enable_rosout=False)
    applied = []

    def even(v):
        if v % 2:
            raise ValueError("must be even")

    try:
        assert node.declare_parameter("rate", 1.0, runtime(applied.append, min_value=0.5,
                                                           max_value=100.0)).value == 4.0
        assert applied == []                       # the start value is the node's to read
        node.declare_parameter("fixed", 3, read_only())
        node.declare_parameter("count", 2, runtime(applied.append, validator=even))
        assert node.set_parameter(roszen.Parameter("rate", value=20.0)).successful
        assert applied == [20.0] and node.get_parameter("rate").value == 20.0
        for bad in (float("nan"), float("inf"), 0.1, 1e6):
            r = node.set_parameter(roszen.Parameter("rate", value=bad))
            assert not r.successful and "rate" in r.reason, (bad, r.reason)
        assert applied == [20.0] and node.get_parameter("rate").value == 20.0
        r = node.set_parameter(roszen.Parameter("count", value=3))
        assert (r.successful, r.reason) == (False, "parameter 'count': must be even")
        assert node.set_parameter(roszen.Parameter("count", value=4)).successful
        r = node.set_parameter(roszen.Parameter("fixed", value=4))
        assert (r.successful, r.reason) == (False, "parameter 'fixed' is read-only")
        assert node.describe_parameter("fixed").read_only
        with pytest.raises(ValueError):            # a bad override ends the node at start
            roszen.Node("n3", argv=["--ros-args", "-p", "rate:=.nan"], use_global_arguments=False,
                        start_parameter_services=False, enable_rosout=False
                        ).declare_parameter("rate", 1.0, runtime(applied.append, min_value=0.5))
    finally:
        node.destroy_node()


def test_apply_failure_keeps_the_old_value(router_env):
    from roszen.parameters import runtime

    def refuse(v):
        raise RuntimeError("hardware busy")

    node = roszen.Node("n4", argv=[], use_global_arguments=False, start_parameter_services=False,
                       enable_rosout=False)
    try:
        node.declare_parameter("gain", 1.0, runtime(refuse))
        r = node.set_parameter(roszen.Parameter("gain", value=2.0))
        assert not r.successful and "hardware busy" in r.reason
        assert node.get_parameter("gain").value == 1.0
    finally:
        node.destroy_node()


def test_wall_clock_timer_runs_while_sim_time_stands_still(router_env):
    """create_timer(clock=Clock(False)) fires on wall time although /clock never advances
    (what a node-loss watchdog needs when the simulator, the clock's source, is gone)."""
    import time
    node = roszen.Node("n5", argv=["--ros-args", "-p", "use_sim_time:=true"],
                       use_global_arguments=False, start_parameter_services=False,
                       enable_rosout=False)
    try:
        fired_sim, fired_wall = [], []
        node.create_timer(0.05, lambda: fired_sim.append(1))
        node.create_timer(0.05, lambda: fired_wall.append(1), clock=roszen.Clock(False))
        end = time.monotonic() + 10.0
        while len(fired_wall) < 3 and time.monotonic() < end:
            node.spin_once(timeout_sec=0.05)
        assert len(fired_wall) >= 3 and fired_sim == []
    finally:
        node.destroy_node()


@pytest.mark.graph
def test_planner_sample_rate_applied_at_run_time(router_env):
    """`astrobee param set /planner_node sample_rate 20.0` changes the next plan's sampling
    (twice the states); NaN, zero and an unknown flight mode are refused with a reason."""
    import subprocess
    import sys
    from pathlib import Path
    astrobee = str(Path(sys.executable).parent / "astrobee")

    def param_set(name, value):
        r = subprocess.run([astrobee, "param", "set", "/planner_node", name, value], env=router_env,
                           capture_output=True, text=True, timeout=60)
        return r.returncode, (r.stdout + r.stderr).strip()

    planner = spawn(python_cmd("-m", "astrobee_planning.planner_node"), router_env)
    node = roszen.Node("planner_user")
    try:
        cli = node.create_client("astrobee_msgs/srv/PlanGlobal", "/mob/planner/global")
        assert cli.wait_for_service(timeout_sec=60.0)

        def n_states():
            req = roszen.request_class("astrobee_msgs/srv/PlanGlobal")()
            req.start.position.x, req.start.position.z = 10.95, 4.84
            req.start.orientation.w = req.goal.orientation.w = 1.0
            req.goal.position.x, req.goal.position.y, req.goal.position.z = 10.93, -1.5, 4.85
            resp = cli.call(req, timeout_sec=60.0)
            assert resp.success, resp.message
            return len(resp.segment)

        before = n_states()
        for bad in (".nan", "0.0", "-3.0"):
            rc, out = param_set("sample_rate", bad)
            assert rc == 1 and "sample_rate" in out, (bad, out)
        rc, out = param_set("flight_mode", "warp")
        assert rc == 1 and "warp" in out, out
        assert param_set("sample_rate", "20.0") == (0, "Set parameter successful")
        after = n_states()
        assert abs(after - 2 * before) <= 2, (before, after)
    finally:
        node.destroy_node()
        stop(planner)
