"""safety:=node and the mission's deterministic start (lockstep, start_paused, --handover): the
mission may reset the sim (the state of t=0 published once) only when the safety filter is
subscribed to the controller's gnc/ctl/command_nominal. A launch timed out 2 times in 7 in the
wait for "the state of t=0 answered by every controller": the recorder (`bag record -a`) had
subscribed command_nominal and the filter had declared its command publisher, not yet its
subscription, so the mission's check (any subscriber of command_nominal, any publisher of
command) passed, and the controller's answer to t=0 went to no filter. Both sides are tested
here with the bad ordering forced: the filter started after the controller and the recorder."""
from __future__ import annotations

import sys
import time

import pytest

from astrobee import msgconv as mc

roszen = pytest.importorskip("roszen")
from roszen import testing  # noqa: E402
from roszen.wire import SUB  # noqa: E402

pytestmark = pytest.mark.graph
PY = sys.executable
NOMINAL = "/gnc/ctl/command_nominal"
COMMAND = "/gnc/ctl/command"


def _spin_until(node, cond, timeout: float, procs=()) -> bool:
    end = time.monotonic() + timeout
    while not cond() and time.monotonic() < end:
        for p in procs:
            assert p.poll() is None, p.stderr.read()[-2000:] if p.stderr else p.returncode
        node.spin_once(timeout_sec=0.05)
    return cond()


def test_filter_declares_its_command_publisher_after_its_inputs(router_env):
    """The filter's publisher of gnc/ctl/command shows in the graph only once every input it
    filters with is subscribed: a publisher of the command means a filter ready to answer."""
    node = roszen.Node("graph_watch")
    graph = node.context.graph
    seen: list[set[str]] = []       # the filter's subscriptions when its command publisher came

    def on_change() -> None:
        pubs = [e for e in graph.get_publishers_info_by_topic(COMMAND)
                if e.node_name == "safety_filter"]
        if pubs and not seen:
            seen.append({e.name for e in graph.entities(SUB) if e.node_name == "safety_filter"})

    graph.add_listener(on_change)
    filt = testing.spawn(testing.python_cmd("-m", "astrobee_control.safety_filter_node",
                                            "--ros-args", "-p", "use_sim_time:=true"), router_env)
    try:
        assert _spin_until(node, lambda: bool(seen), 60.0, (filt,)), "no filter publisher"
    finally:
        graph.remove_listener(on_change)
        testing.stop(filt)
    assert {NOMINAL, "/" + mc.EKF, "/" + mc.FLIGHT_MODE, mc.SIM_SCENARIO,
            mc.BAG_STATE} <= seen[0], seen[0]


def test_deterministic_start_waits_for_a_filter_subscribed_to_the_nominal_command(router_env):
    """sim_node (rigid, lockstep, start_paused) and a PD controller remapped to
    command_nominal run; a recorder's subscription of command_nominal and a half-started filter
    (its command publisher only) are in the graph: the mission's check says the filter is
    missing (it said ready, and the leg then timed out). The filter then starts: the paused
    reset completes, the controller's answer to t=0 relayed to gnc/ctl/command."""
    from astrobee_bringup.mission import MissionClient

    sim = testing.spawn([PY, "-m", "astrobee_sim.sim_node", "--ros-args", "-p", "backend:=rigid",
                         "-p", "scenario:=node2_to_jem", "-p", "clock_mode:=lockstep",
                         "-p", "start_paused:=true", "-p", "lockstep_timeout:=60.0"], router_env)
    ctl = testing.spawn([PY, "-m", "astrobee_control.pd_controller_node", "--ros-args",
                         "-p", "use_sim_time:=true", "-r", f"gnc/ctl/command:={NOMINAL[1:]}"],
                        router_env)
    procs = [sim, ctl]
    try:
        node = roszen.Node("mission")
        recorder = roszen.Node("rosbag2_recorder")        # `bag record -a`: every topic
        recorder.create_subscription("astrobee_msgs/msg/FamCommand", NOMINAL, lambda m: None, 10)
        half = roszen.Node("safety_filter")               # the old filter, mid-construction
        half.create_publisher("astrobee_msgs/msg/FamCommand", COMMAND, 10)
        client = MissionClient(node, handover=True)
        w = client.watch("")
        assert _spin_until(node, lambda: w.mob_state is not None
                           and node.count_publishers(NOMINAL) > 0
                           and client.scenario_info is not None, 90.0, procs), "no controller"
        why = client._graph_not_ready([""])
        assert "relaying" in why and NOMINAL in why, why
        half.destroy_node()
        assert "no publisher" in client._graph_not_ready([""])
        procs.append(testing.spawn(testing.python_cmd(
            "-m", "astrobee_control.safety_filter_node", "--ros-args", "-p", "use_sim_time:=true"),
            router_env))
        client._paused_reset("node2_to_jem", ready_timeout=90.0)     # MissionError if not
        assert w.cmd_ns == 0 and w.sim_time == 0.0
        assert client._graph_not_ready([""]) == ""
        recorder.destroy_node()
        node.destroy_node()
    finally:
        for p in reversed(procs):
            testing.stop(p, timeout=5.0)
