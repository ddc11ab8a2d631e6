"""safety_filter_node in the graph: router + sim_node (lockstep) + safety_filter_node +
this test acting as a broken controller commanding full thrust at the nearest wall; the filter
keeps the robot off the wall and says it intervened."""

import numpy as np
import pytest

from astrobee import flight_modes
from astrobee import msgconv as mc
from astrobee_control import safety_filter_node as sfn
from astrobee_control.node_io import SAFETY


def test_topic_names():
    assert sfn.COMMAND_NOMINAL == "gnc/ctl/command_nominal"
    assert SAFETY == "gnc/ctl/safety"
    assert mc.COMMAND == "gnc/ctl/command"


# node2_to_jem starts at [10.95, 0, 4.84] facing -y (body x = world -y, body y = world +x, body z =
# world +z). Leaving the keep-in union from there takes 1.14 m along world +x (the end of the
# forward corridor: the nearest wall), 1.22 m along +z, but 18 m along -x (the hatch to the
# Lab): body +y and body +z drive into walls.
@pytest.mark.graph
@pytest.mark.parametrize("body_axis, world_dir", [(1, (1.0, 0.0, 0.0)), (2, (0.0, 0.0, 1.0))],
                         ids=["body+y_world+x", "body+z_world+z"])
def test_full_thrust_at_a_wall_is_stopped_through_the_graph(router_env, body_axis, world_dir):
    import roszen
    from roszen import testing

    sim = testing.spawn(testing.python_cmd("-m", "astrobee_sim.sim_node", "--ros-args", "-p",
                                           "scenario:=node2_to_jem", "-p", "clock_mode:=lockstep"),
                        router_env)
    filt = testing.spawn(testing.python_cmd("-m", "astrobee_control.safety_filter_node",
                                            "--ros-args", "-p", "use_sim_time:=true"), router_env)
    procs = (sim, filt)
    try:
        node = roszen.Node("broken_controller")
        force = np.zeros(3)
        force[body_axis] = flight_modes.get("nominal").max_force[body_axis]
        FamCommand = roszen.message_class("astrobee_msgs/msg/FamCommand")
        pub = node.create_publisher("astrobee_msgs/msg/FamCommand", sfn.COMMAND_NOMINAL, 10)
        states, contacts, diags, filtered = [], [], [], []

        def on_ekf(m):
            t = mc.stamp_s(m.header.stamp)
            states.append((t, mc.vec(m.pose.position), mc.vec(m.velocity)))
            c = FamCommand()
            c.header.stamp = m.header.stamp
            c.header.frame_id = "body"
            mc.set_vec(c.wrench.force, force)
            c.control_mode = 2
            pub.publish(c)

        node.create_subscription("astrobee_msgs/msg/EkfState", "/" + mc.EKF, on_ekf, 50)
        node.create_subscription("astrobee_msgs/msg/Contacts", mc.CONTACTS,
                                 lambda m: contacts.append((m.in_contact, m.robot_clearance)), 50)
        node.create_subscription("astrobee_msgs/msg/FamCommand", "/" + mc.COMMAND,
                                 lambda m: filtered.append((mc.stamp_s(m.header.stamp),
                                                            mc.vec(m.wrench.force), m.control_mode)),
                                 50)
        node.create_subscription(
            "diagnostic_msgs/msg/DiagnosticArray", "/" + SAFETY,
            lambda m: diags.append((m.status[0].level, {kv.key: kv.value for kv in m.status[0].values})),
            roszen.LATCHED)

        assert testing.spin_until(node, lambda: states and states[-1][0] >= 15.0, 240.0, procs), \
            states[-1:] or "no state"
        start = states[0][1]
        # the filter's output keeps the nominal command's stamp (the lockstep advanced on it)
        assert filtered and filtered[-1][2] == 2
        assert contacts, "no /sim/contacts"
        assert not any(c for c, _ in contacts), "the robot touched a wall"
        clear = [d for _, d in contacts if d >= 0]
        assert clear and min(clear) > 0.0, min(clear)
        # it moved toward the wall, then was held off it: it comes to rest short of it
        end = states[-1]
        assert float((end[1] - start) @ np.asarray(world_dir)) > 0.3, (start, end[1])
        assert float(np.linalg.norm(end[2])) < 0.05, end[2]
        # the filter reported it intervened (WARN, active) and never crashed
        assert any(level in (1, 2) and kv["active"] == "true" for level, kv in diags), diags[-3:]
        assert {"active", "delta_norm", "slack", "min_barrier", "omega_barrier", "fallback",
                "reason"} <= set(diags[-1][1])
    finally:
        for p in procs:
            testing.stop(p)
