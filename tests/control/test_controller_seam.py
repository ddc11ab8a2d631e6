"""The control-law seam: a second, trivial law (HoldLaw) flies through the graph in
controller_node (router + sim_node + the law's node + this test: four processes), and the
transport-free layers load no zenoh."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from astrobee import msgconv as mc
from astrobee_control.hold import HoldLaw
from astrobee_control.law import ControlLaw
from astrobee_control.tracking import Tracker

HERE = Path(__file__).resolve().parent


def test_laws_implement_the_protocol():
    from astrobee import flight_modes
    from astrobee_control import mass as mp
    for law in (Tracker(flight_modes.get(None), mp.robot()), HoldLaw(flight_modes.get(None), mp.robot())):
        assert isinstance(law, ControlLaw), law


def test_motion_state_constants_match_the_message():
    from astrobee.config import msgs_dir
    text = (msgs_dir() / "msg" / "MotionState.msg").read_text()
    consts = {}
    for line in text.splitlines():
        parts = line.split()
        if len(parts) == 4 and parts[0] == "uint8" and parts[2] == "=":
            consts[parts[1]] = int(parts[3])
    assert consts and all(getattr(mc.MotionState, k) == v for k, v in consts.items())
    assert mc.MotionState.NAMES == {v: k for k, v in consts.items()}


def test_stamp_rule_never_goes_back():
    class T:
        sec = nanosec = 0
    s = T()
    for t in (0.0, 0.9999999999, 1.0, 1.5, 2.9999999996, 1e4 + 0.123456789):
        mc.set_stamp(s, t)
        assert 0 <= s.nanosec < 1_000_000_000
        assert abs(mc.stamp_s(s) - t) <= 1e-9
    mc.set_stamp(s, -3.0)
    assert (s.sec, s.nanosec) == (0, 0)


def test_core_and_libraries_load_no_transport():
    """Importing rotations, the planner, the control laws and the simulator library loads no
    zenoh and no roszen (a rollout worker must not pay for the transport)."""
    code = ("import sys\n"
            "import astrobee, astrobee.rotations, astrobee.config, astrobee.flight_modes\n"
            "import astrobee.scenario, astrobee.msgconv\n"
            "import astrobee_planning.planner, astrobee_planning.local_planner\n"
            "import astrobee_control.tracking, astrobee_control.hold, astrobee_control.law\n"
            "import astrobee_sim.simulation\n"
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('zenoh', 'roszen'))\n"
            "print(bad)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", out.stdout


@pytest.mark.graph
def test_hold_law_runs_in_controller_node_through_the_graph(router_env):
    import roszen
    from roszen import testing
    sim = testing.spawn(testing.python_cmd("-m", "astrobee_sim.sim_node", "--ros-args", "-p",
                                           "scenario:=node2_to_jem", "-p", "clock_mode:=lockstep"),
                        router_env)
    ctl = testing.spawn(testing.python_cmd(str(HERE / "hold_node.py"), "--ros-args", "-p",
                                           "use_sim_time:=true"), router_env)
    try:
        node = roszen.Node("hold_test")
        poses, states = [], []
        node.create_subscription("geometry_msgs/msg/PoseStamped", "/loc/truth/pose",
                                 lambda m: poses.append((mc.stamp_s(m.header.stamp), mc.vec(m.pose.position))), 50)
        node.create_subscription("astrobee_msgs/msg/MotionState", "/mob/state",
                                 lambda m: states.append((m.state, m.fsm_state, m.fsm_event)), roszen.LATCHED)
        commands = []
        node.create_subscription("astrobee_msgs/msg/FamCommand", "/gnc/ctl/command",
                                 lambda m: commands.append(m.control_mode), 50)

        # lockstep: the sim only advances on the hold law's commands. Wait for both topics: a
        # test process starved of CPU may first hear the sim at t >= 3 s, before any command
        assert testing.spin_until(node, lambda: poses and poses[-1][0] >= 3.0
                                  and len(commands) >= 10, 90.0, (sim, ctl)), \
            (poses[-1:] or "no pose", len(commands))
        start = poses[0][1]
        assert float(np.linalg.norm(poses[-1][1] - start)) < 0.01
        assert commands and all(c == 1 for c in commands[-10:])       # MODE_STOP: holding
        assert states and states[-1][0] == mc.MotionState.STOPPED
        # a segment is refused by this law and the robot keeps holding
        seg = roszen.message_class("astrobee_msgs/msg/Segment")()
        cs = roszen.message_class("astrobee_msgs/msg/ControlState")
        for k in range(3):
            m = cs()
            mc.set_stamp(m.when, poses[-1][0] + k)
            mc.set_pose(m.pose, start + [0.0, -0.1 * k, 0.0], [0, 0, -0.7071068, 0.7071068])
            seg.segment.append(m)
        mc.set_stamp(seg.header.stamp, poses[-1][0])
        pub = node.create_publisher("astrobee_msgs/msg/Segment", "/gnc/ctl/segment", roszen.LATCHED)
        pub.publish(seg)
        assert testing.spin_until(node, lambda: any("REFUSED" in s[2] or "refused" in s[2] for s in states), 30.0,
                                  (sim, ctl)), states
        t_seg = poses[-1][0]
        assert testing.spin_until(node, lambda: poses[-1][0] >= t_seg + 2.0, 60.0, (sim, ctl))
        assert float(np.linalg.norm(poses[-1][1] - start)) < 0.01
    finally:
        for p in (ctl, sim):
            testing.stop(p)
