"""pd_controller_node in its own process, driven in lockstep by a numpy rigid body in the test
process acting as the simulator (router + controller + test node: three processes)."""
import time

import numpy as np
import pytest

from astrobee import rotations as rot
from astrobee_control import mass as mp
from astrobee_control.reference import rest_to_rest
from astrobee_control.rigid_body import RigidBody

roszen = pytest.importorskip("roszen")
from roszen import testing  # noqa: E402

pytestmark = pytest.mark.graph
DT = 1.0 / 62.5


class FakeSim:
    """Publishes EkfState, waits for the command of that stamp, applies it to a rigid body."""

    def __init__(self, node, body):
        from roszen import Durability, QoSProfile
        self.node, self.body, self.t = node, body, 0.0
        self.Ekf = roszen.message_class("astrobee_msgs/msg/EkfState")
        self.pub = node.create_publisher("astrobee_msgs/msg/EkfState", "/gnc/ekf", 10)
        self.commands, self.states = {}, []
        node.create_subscription("astrobee_msgs/msg/FamCommand", "/gnc/ctl/command", self._on_cmd, 50)
        latched = QoSProfile(depth=1, durability=Durability.TRANSIENT_LOCAL)
        node.create_subscription("astrobee_msgs/msg/MotionState", "/mob/state",
                                 lambda m: self.states.append((int(m.state), m.fsm_event)), latched)
        self.seg_pub = node.create_publisher("astrobee_msgs/msg/Segment", "/gnc/ctl/segment", latched)

    def _on_cmd(self, m):
        self.commands[(m.header.stamp.sec, m.header.stamp.nanosec)] = m

    def tick(self, timeout=5.0):
        s = self.body.state()
        m = self.Ekf()
        sec = int(self.t)
        m.header.stamp.sec, m.header.stamp.nanosec = sec, int(round((self.t - sec) * 1e9))
        key = (m.header.stamp.sec, m.header.stamp.nanosec)
        m.pose.position.x, m.pose.position.y, m.pose.position.z = s.position
        (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
         m.pose.orientation.w) = s.orientation
        m.velocity.x, m.velocity.y, m.velocity.z = s.velocity
        m.omega.x, m.omega.y, m.omega.z = s.omega
        end = time.monotonic() + timeout
        next_pub = 0.0
        while key not in self.commands:
            if time.monotonic() > next_pub:  # resend until the controller is up and answers
                self.pub.publish(m)
                next_pub = time.monotonic() + 0.5
            assert time.monotonic() < end, f"no command for stamp {key}"
            self.node.spin_once(timeout_sec=0.01)
        c = self.commands.pop(key)
        f = np.array([c.wrench.force.x, c.wrench.force.y, c.wrench.force.z])
        tq = np.array([c.wrench.torque.x, c.wrench.torque.y, c.wrench.torque.z])
        for _ in range(2):
            self.body.step(f, tq, DT / 2)
        self.t += DT
        return c, f


def segment_msg(traj):
    seg = roszen.message_class("astrobee_msgs/msg/Segment")()
    CS = roszen.message_class("astrobee_msgs/msg/ControlState")
    seg.header.stamp.sec = 1
    seg.flight_mode = "nominal"
    out = []
    for i, t in enumerate(traj.t):
        c = CS()
        c.when.sec, c.when.nanosec = int(t), int(round((t - int(t)) * 1e9))
        c.pose.position.x, c.pose.position.y, c.pose.position.z = traj.position[i]
        (c.pose.orientation.x, c.pose.orientation.y, c.pose.orientation.z,
         c.pose.orientation.w) = traj.orientation[i]
        c.twist.linear.x, c.twist.linear.y, c.twist.linear.z = traj.velocity[i]
        c.accel.linear.x, c.accel.linear.y, c.accel.linear.z = traj.accel[i]
        out.append(c)
    seg.segment = out
    return seg


@pytest.fixture
def graph():
    with testing.router() as port:
        env = testing.zenoh_env(port)
        ctl = testing.spawn(testing.python_cmd("-m", "astrobee_control.pd_controller_node"), env)
        ctx = roszen.Context(env=env)
        node = roszen.Node("fake_sim", context=ctx)
        try:
            yield node
        finally:
            node.destroy_node()
            ctx.shutdown()
            code = testing.stop(ctl)
            assert code is not None


def test_node_follows_segment_and_stops_at_goal(graph):
    q = rot.from_axis_angle([0, 0, 1], -np.pi / 2)  # yawed: world -y is body +x
    p0, p1 = np.array([10.95, 0.0, 4.84]), np.array([10.95, -1.0, 4.84])
    body = RigidBody(mp.robot(), p0, q)
    sim = FakeSim(graph, body)
    for _ in range(10):
        sim.tick(timeout=20.0)
    traj = rest_to_rest(p0, p1, q, q, 12.0)
    sim.seg_pub.publish(segment_msg(traj))
    forces = []
    for _ in range(int(25.0 / DT)):
        c, f = sim.tick()
        forces.append(f)
        graph.spin_once(timeout_sec=0)
        if sim.states and sim.states[-1][0] == 2 and any(s == 9 for s, _ in sim.states):
            break
    seq = [s for s, _ in sim.states]
    assert 9 in seq and seq[-1] == 2, seq
    assert seq.index(4, seq.index(9)) > seq.index(9)  # STOPPING after CONTROLLING
    assert np.linalg.norm(body.state().position - p1) < 0.05
    # motion is along world -y = body +x: the accelerating force is mostly on body x
    f = np.array(forces)
    assert np.max(f[:, 0]) > 5 * np.max(np.abs(f[:, 1]))


def test_stop_service_holds_pose(graph):
    p0, p1 = np.zeros(3), np.array([2.0, 0.0, 0.0])
    body = RigidBody(mp.robot(), p0, rot.IDENTITY)
    sim = FakeSim(graph, body)
    sim.tick(timeout=20.0)
    sim.seg_pub.publish(segment_msg(rest_to_rest(p0, p1, rot.IDENTITY, rot.IDENTITY, 20.0)))
    for _ in range(int(8.0 / DT)):
        sim.tick()
    cli = graph.create_client("std_srvs/srv/Trigger", "/gnc/ctl/stop")
    assert cli.wait_for_service(timeout_sec=5.0)
    fut = cli.call_async(roszen.request_class("std_srvs/srv/Trigger")())
    while not fut.done():  # keep the lockstep going while the service answers
        sim.tick()
    assert fut.result().success
    x_stop = body.state().position[0]
    for _ in range(int(15.0 / DT)):
        sim.tick()
    graph.spin_once(timeout_sec=0.1)
    assert sim.states[-1][0] == 2  # STOPPED
    assert abs(body.state().position[0] - x_stop) < 0.1
    assert body.state().position[0] < 1.5


def test_bad_segment_rejected_node_keeps_holding(graph):
    p0 = np.array([1.0, 2.0, 3.0])
    body = RigidBody(mp.robot(), p0, rot.IDENTITY)
    sim = FakeSim(graph, body)
    sim.tick(timeout=20.0)
    seg = segment_msg(rest_to_rest(p0, p0 + 1.0, rot.IDENTITY, rot.IDENTITY, 5.0))
    seg.segment[3].pose.position.x = float("nan")
    sim.seg_pub.publish(seg)
    for _ in range(int(3.0 / DT)):
        sim.tick()
    graph.spin_once(timeout_sec=0.1)
    assert any("rejected" in e for _, e in sim.states), sim.states
    assert 9 not in [s for s, _ in sim.states]  # never CONTROLLING
    assert sim.states[-1][0] == 2  # still holding (STOPPED)
    assert np.linalg.norm(body.state().position - p0) < 1e-3
