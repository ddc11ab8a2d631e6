"""The controller process killed mid-flight: the sim's propulsion watchdog raises a fault and
the robot coasts (no thrust: its speed does not grow). Router, sim_node (lockstep) and
pd_controller_node in their own processes; the test node hands the segment and watches."""
from __future__ import annotations

import time

import numpy as np
import pytest

roszen = pytest.importorskip("roszen")
pytest.importorskip("astrobee_sim.sim_node")
from roszen import testing  # noqa: E402

from astrobee import config  # noqa: E402
from astrobee_control.reference import rest_to_rest  # noqa: E402

pytestmark = pytest.mark.graph


def segment(traj):
    seg = roszen.message_class("astrobee_msgs/msg/Segment")()
    CS = roszen.message_class("astrobee_msgs/msg/ControlState")
    seg.header.stamp.sec, seg.flight_mode = 1, "nominal"
    out = []
    for i, t in enumerate(traj.t):
        c = CS()
        c.when.sec, c.when.nanosec = int(t), int(round((t - int(t)) * 1e9))
        c.pose.position.x, c.pose.position.y, c.pose.position.z = traj.position[i]
        o = c.pose.orientation
        o.x, o.y, o.z, o.w = traj.orientation[i]
        c.twist.linear.x, c.twist.linear.y, c.twist.linear.z = traj.velocity[i]
        c.accel.linear.x, c.accel.linear.y, c.accel.linear.z = traj.accel[i]
        out.append(c)
    seg.segment = out
    return seg


def test_controller_killed_watchdog_stops_thrust():
    scen = config.scenario("node2_to_jem")
    r = scen["robots"][0]
    p0, q0 = np.array(r["position"]), np.array(r["orientation"])
    with testing.router() as port:
        env = testing.zenoh_env(port)
        sim = testing.spawn(testing.python_cmd(
            "-m", "astrobee_sim.sim_node", "--ros-args", "-p", "scenario:=node2_to_jem",
            "-p", "clock_mode:=lockstep", "-p", "lockstep_timeout:=0.05"), env)
        # without a controller every tick waits lockstep_timeout: the 2 s of sim time watched
        # after the kill (125 ticks) take ~6 s of wall time at 0.05 s (25 s at 0.2 s)
        ctl = testing.spawn(testing.python_cmd(
            "-m", "astrobee_control.pd_controller_node", "--ros-args", "-p", "use_sim_time:=true"), env)
        ctx = roszen.Context(env=env)
        node = roszen.Node("watcher", context=ctx)
        try:
            faults, twists = [], []
            node.create_subscription("astrobee_msgs/msg/Fault", "/sim/fault",
                                     lambda m: faults.append((m.active, m.message)), roszen.LATCHED)
            node.create_subscription(
                "geometry_msgs/msg/TwistStamped", "/loc/truth/twist",
                lambda m: twists.append((m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec,
                                         float(np.linalg.norm([m.twist.linear.x, m.twist.linear.y,
                                                               m.twist.linear.z])))), 100)
            pub = node.create_publisher("astrobee_msgs/msg/Segment", "/gnc/ctl/segment", roszen.LATCHED)
            pub.publish(segment(rest_to_rest(p0, p0 + [0.0, -2.0, 0.0], q0, q0, 20.0)))
            end = time.monotonic() + 90
            while not (twists and twists[-1][1] > 0.05):
                assert time.monotonic() < end, "robot never got going"
                node.spin_once(timeout_sec=0.05)
            testing.kill9(ctl)
            t_kill, v_kill = twists[-1]
            end = time.monotonic() + 60
            while not (twists and twists[-1][0] > t_kill + 2.0):
                assert time.monotonic() < end, "sim did not run on after the controller died"
                node.spin_once(timeout_sec=0.05)
            node.spin_once(timeout_sec=0.2)
            assert any(active for active, _ in faults), faults
            after = [v for t, v in twists if t > t_kill + 0.5]
            assert after and max(after) <= v_kill + 0.01   # no thrust: the speed does not grow
            assert sim.poll() is None                       # the sim survives its controller
        finally:
            node.destroy_node()
            ctx.shutdown()
            testing.stop(ctl)
            testing.stop(sim)
