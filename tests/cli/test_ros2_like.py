"""ros2-like behaviour users expect: `-r __ns:=` moves the planner's topics and
services; `topic echo` with a type says when the topic is unknown or published under another
type; one "no router" warning, worded once."""
from __future__ import annotations

import subprocess
import time

import pytest

from conftest import ASTROBEE, graph_env

pytestmark = pytest.mark.graph


def _run(env, *args, timeout=30):
    return subprocess.run([ASTROBEE, *args], env=env, capture_output=True, text=True,
                          timeout=timeout)


def test_namespace_moves_the_planner(procs, env):
    procs([ASTROBEE, "run", "astrobee_planning", "planner_node", "--ros-args",
               "-r", "__ns:=/bumble"], env=env)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        services = _run(env, "service", "list").stdout.split()
        if "/bumble/mob/planner/global" in services:
            break
        time.sleep(0.5)
    assert {"/bumble/mob/planner/global", "/bumble/mob/planner/local"} <= set(services)
    assert "/mob/planner/global" not in services
    topics = _run(env, "topic", "list").stdout.split()
    assert "/bumble/mob/planner/path" in topics and "/mob/planner/path" not in topics


def test_echo_with_a_mismatched_type_says_so(procs, env):
    pub = procs([ASTROBEE, "topic", "pub", "-r", "10", "/count", "std_msgs/msg/Int32",
                 "{data: 3}"], env=env)
    pub.wait_line("publishing #1")
    r = _run(env, "topic", "echo", "/count", "std_msgs/msg/String", "--discovery-timeout", "1")
    assert r.returncode == 1
    assert r.stderr.strip() == ("astrobee topic echo: '/count' is published as "
                                "std_msgs/msg/Int32, not std_msgs/msg/String")


def test_echo_with_a_type_on_an_unknown_topic_warns_then_waits(procs, env):
    echo = procs([ASTROBEE, "topic", "echo", "/nobody", "std_msgs/msg/String",
                  "--discovery-timeout", "0.5"], env=env)
    line = echo.wait_line("no publisher", stream="err")
    assert line == ("[WARN] no publisher on '/nobody' yet (waited 0.5 s); waiting for one of "
                    "type std_msgs/msg/String")
    assert echo.popen.poll() is None          # still waiting, as ros2 topic echo does
    procs([ASTROBEE, "topic", "pub", "-r", "10", "/nobody", "std_msgs/msg/String",
           "{data: late}"], env=env)
    echo.wait_line("data: late", timeout=30)


def test_one_no_router_warning(port):
    env = graph_env(port)          # nothing listens on this port
    env["ROSZEN_ROUTER_WAIT"] = "0.3"
    r = _run(env, "topic", "list")
    warnings = [l for l in r.stderr.splitlines() if "router" in l]
    assert len(warnings) == 1, r.stderr
    assert "no Zenoh router reachable (start one with `astrobee router`" in warnings[0]
