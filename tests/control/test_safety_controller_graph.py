"""pd_controller_node with safety:=true in the graph: router + sim_node (numpy rigid
backend, lockstep) + the controller, whose segment is aimed through the nearest wall; the
CBF filter inside the controller's process stops the robot short of the wall and publishes its
latched diagnostics on /gnc/ctl/safety (no safety_filter_node, no command_nominal topic)."""

import numpy as np
import pytest

from astrobee import msgconv as mc
from astrobee_control.reference import rest_to_rest

pytestmark = pytest.mark.graph

# node2_to_jem starts at [10.95, 0, 4.84] facing -y; the end of the forward corridor (the
# nearest wall) is ~1.1 m along world +x: the segment asks for 2.5 m
START = np.array([10.95, 0.0, 4.84])
THROUGH_WALL = START + np.array([2.5, 0.0, 0.0])


def segment_msg(roszen, traj, t0: float):
    """The trajectory as a Segment, its times shifted by t0 (s of sim time)."""
    seg = roszen.message_class("astrobee_msgs/msg/Segment")()
    CS = roszen.message_class("astrobee_msgs/msg/ControlState")
    mc.set_stamp(seg.header.stamp, t0)
    seg.flight_mode = "nominal"
    out = []
    for i, t in enumerate(traj.t):
        c = CS()
        mc.set_stamp(c.when, t0 + float(t))
        mc.set_pose(c.pose, traj.position[i], traj.orientation[i])
        mc.set_vec(c.twist.linear, traj.velocity[i])
        mc.set_vec(c.accel.linear, traj.accel[i])
        out.append(c)
    seg.segment = out
    return seg


def test_controller_with_safety_stops_short_of_the_wall(router_env):
    import roszen
    from roszen import testing

    sim = testing.spawn(testing.python_cmd(
        "-m", "astrobee_sim.sim_node", "--ros-args", "-p", "backend:=rigid",
        "-p", "scenario:=node2_to_jem", "-p", "clock_mode:=lockstep",
        "-p", "lockstep_timeout:=20.0", "-p", "lockstep_start_timeout:=120.0"), router_env)
    ctl = testing.spawn(testing.python_cmd(
        "-m", "astrobee_control.pd_controller_node", "--ros-args", "-p", "use_sim_time:=true",
        "-p", "safety:=true"), router_env)
    procs = (sim, ctl)
    node = roszen.Node("wall_test")
    try:
        states, contacts, diags, commands = [], [], [], []
        node.create_subscription("astrobee_msgs/msg/EkfState", "/" + mc.EKF,
                                 lambda m: states.append((mc.stamp_s(m.header.stamp),
                                                          mc.vec(m.pose.position),
                                                          mc.vec(m.velocity))), 50)
        node.create_subscription("astrobee_msgs/msg/Contacts", mc.CONTACTS,
                                 lambda m: contacts.append((m.in_contact, m.robot_clearance)), 50)
        node.create_subscription("astrobee_msgs/msg/FamCommand", "/" + mc.COMMAND,
                                 lambda m: commands.append(mc.stamp_s(m.header.stamp)), 50)
        node.create_subscription(
            "diagnostic_msgs/msg/DiagnosticArray", "/gnc/ctl/safety",
            lambda m: diags.append((m.status[0].level, m.status[0].hardware_id,
                                    {kv.key: kv.value for kv in m.status[0].values})),
            roszen.QoSProfile(depth=50, durability=roszen.Durability.TRANSIENT_LOCAL))
        seg_pub = node.create_publisher("astrobee_msgs/msg/Segment", "/" + mc.SEGMENT,
                                        roszen.LATCHED)

        assert testing.spin_until(node, lambda: commands and states and states[-1][0] >= 0.5, 180.0, procs), \
            "the controller never closed the loop"
        t0 = states[-1][0] + 0.5
        q = np.array([0.0, 0.0, -np.sqrt(0.5), np.sqrt(0.5)])
        seg_pub.publish(segment_msg(roszen, rest_to_rest(START, THROUGH_WALL, q, q, 8.0), t0))
        assert testing.spin_until(node, lambda: states[-1][0] >= t0 + 14.0, 240.0, procs), states[-1][0]
        # nobody publishes the nominal topic: the filter is inside the controller
        assert not node.get_publishers_info_by_topic("/gnc/ctl/command_nominal")
        assert contacts and not any(c for c, _ in contacts), "the robot touched a wall"
        clear = [d for _, d in contacts if d >= 0]
        assert clear and min(clear) > 0.0, min(clear)
        end = states[-1]
        assert end[1][0] - START[0] > 0.3, end[1]                  # it flew toward the wall
        assert end[1][0] < THROUGH_WALL[0] - 1.0, end[1]           # and stopped well short
        assert float(np.linalg.norm(end[2])) < 0.05, end[2]        # at rest
        # the filter said it intervened, with the diagnostics safety_filter_node publishes
        assert any(level in (1, 2) and kv["active"] == "true" for level, _, kv in diags), diags[-3:]
        assert {"active", "delta_norm", "slack", "min_barrier", "omega_barrier", "fallback",
                "reason", "ticks", "active_ticks", "fallback_ticks"} <= set(diags[-1][2])
        assert int(diags[-1][2]["active_ticks"]) > 0
    finally:
        node.destroy_node()
        for p in (sim, ctl):              # the sim first: it waits on the controller
            testing.stop(p)
