"""pd_controller_node in its own process, closing the loop in lockstep with sim_node on its numpy
rigid-body backend (backend:=rigid; router + sim + controller + test node: four processes). The
robot starts where each test puts it (a scenario written to a copy of config/)."""
import shutil
import time

import numpy as np
import pytest
import yaml

from astrobee import config
from astrobee import rotations as rot
from astrobee_control.reference import rest_to_rest

roszen = pytest.importorskip("roszen")
from roszen import testing  # noqa: E402

pytestmark = pytest.mark.graph
DT = 1.0 / 62.5


class SimWatch:
    """The test's view of the loop: poses and commands as they pass, the controller's
    MotionState, and the segment publisher; waits are bounded in wall time and sim time."""

    def __init__(self, node, procs):
        from roszen import Durability, QoSProfile
        self.node, self.procs = node, procs
        self.poses, self.forces, self.states = [], [], []
        node.create_subscription("geometry_msgs/msg/PoseStamped", "/loc/truth/pose", self._on_pose, 50)
        node.create_subscription("astrobee_msgs/msg/FamCommand", "/gnc/ctl/command", self._on_cmd, 50)
        latched = QoSProfile(depth=1, durability=Durability.TRANSIENT_LOCAL)
        # a deep queue: CONTROLLING -> STOPPING -> STOPPED can come within one spin on a loaded
        # machine, and a depth-1 queue would keep only the last (the late-joiner copy is one)
        history = QoSProfile(depth=50, durability=Durability.TRANSIENT_LOCAL)
        node.create_subscription("astrobee_msgs/msg/MotionState", "/mob/state",
                                 lambda m: self.states.append((int(m.state), m.fsm_event)), history)
        self.seg_pub = node.create_publisher("astrobee_msgs/msg/Segment", "/gnc/ctl/segment", latched)
        self.refs = []
        node.create_subscription("astrobee_msgs/msg/ControlState", "/gnc/ctl/traj",
                                 lambda m: self.refs.append(np.array([m.pose.position.x, m.pose.position.y,
                                                                      m.pose.position.z])), 50)

    def _on_pose(self, m):
        p = m.pose.position
        self.poses.append((m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec, np.array([p.x, p.y, p.z])))

    def _on_cmd(self, m):
        f = m.wrench.force
        self.forces.append(np.array([f.x, f.y, f.z]))

    @property
    def t(self):
        return self.poses[-1][0] if self.poses else -1.0

    def position(self):
        return self.poses[-1][1]

    def spin_until(self, cond, timeout=120.0):
        end = time.monotonic() + timeout
        while not cond():
            for p in self.procs:
                assert p.poll() is None, f"process exited {p.returncode}: {p.stderr.read()[-2000:]}"
            assert time.monotonic() < end, "timed out"
            self.node.spin_once(timeout_sec=0.01)

    def run_for(self, seconds, until=lambda: False):
        """Let sim time advance by `seconds` (or until `until()`)."""
        t_end = self.t + seconds
        self.spin_until(lambda: self.t >= t_end or until())

    def commanded(self):
        """Wait for the controller to close the loop (its commands arriving)."""
        self.spin_until(lambda: self.forces and self.t >= DT)


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
def graph(tmp_path):
    """make(p0, q0) -> SimWatch: router, sim_node (rigid, lockstep) starting at p0/q0, the
    controller, and the test node."""
    cfg = tmp_path / "config"
    shutil.copytree(config.config_dir(), cfg)
    with testing.router() as port:
        env = dict(testing.zenoh_env(port), ASTROBEE_CONFIG_DIR=str(cfg))
        procs, nodes = [], []

        def make(p0, q0):
            sc = {"description": "pd node test start", "flight_mode": "nominal", "bag": None,
                  "robots": [{"name": "", "position": [float(x) for x in p0],
                              "orientation": [float(x) for x in q0]}]}
            (cfg / "scenarios" / "pd_test.yaml").write_text(yaml.safe_dump(sc))
            procs.append(testing.spawn(testing.python_cmd(
                "-m", "astrobee_sim.sim_node", "--ros-args", "-p", "backend:=rigid",
                "-p", "scenario:=pd_test", "-p", "clock_mode:=lockstep",
                "-p", "lockstep_timeout:=20.0", "-p", "lockstep_start_timeout:=120.0"), env))
            procs.append(testing.spawn(testing.python_cmd(
                "-m", "astrobee_control.pd_controller_node", "--ros-args", "-p", "use_sim_time:=true"), env))
            ctx = roszen.Context(env=env)
            node = roszen.Node("pd_test", context=ctx)
            nodes.append((node, ctx))
            watch = SimWatch(node, procs)
            watch.env = env               # for CLI calls into this graph
            return watch
        try:
            yield make
        finally:
            for node, ctx in nodes:
                node.destroy_node()
                ctx.shutdown()
            for p in procs:                  # the sim first: it waits on the controller
                assert testing.stop(p) is not None


def test_node_follows_segment_and_stops_at_goal(graph):
    q = rot.from_axis_angle([0, 0, 1], -np.pi / 2)  # yawed: world -y is body +x
    p0, p1 = np.array([10.95, 0.0, 4.84]), np.array([10.95, -1.0, 4.84])
    sim = graph(p0, q)
    sim.commanded()
    sim.run_for(10 * DT)
    traj = rest_to_rest(p0, p1, q, q, 12.0)
    k = len(sim.forces)
    sim.seg_pub.publish(segment_msg(traj))
    sim.run_for(25.0, until=lambda: sim.states and sim.states[-1][0] == 2
                and any(s == 9 for s, _ in sim.states))
    sim.node.spin_once(timeout_sec=0)
    seq = [s for s, _ in sim.states]
    assert 9 in seq and seq[-1] == 2, seq
    assert seq.index(4, seq.index(9)) > seq.index(9)  # STOPPING after CONTROLLING
    assert np.linalg.norm(sim.position() - p1) < 0.05
    # motion is along world -y = body +x: the accelerating force is mostly on body x
    f = np.array(sim.forces[k:])
    assert np.max(f[:, 0]) > 5 * np.max(np.abs(f[:, 1]))


def test_stop_service_holds_pose(graph):
    p0, p1 = np.zeros(3), np.array([2.0, 0.0, 0.0])
    sim = graph(p0, rot.IDENTITY)
    sim.commanded()
    sim.seg_pub.publish(segment_msg(rest_to_rest(p0, p1, rot.IDENTITY, rot.IDENTITY, 20.0)))
    sim.run_for(8.0)
    cli = sim.node.create_client("std_srvs/srv/Trigger", "/gnc/ctl/stop")
    assert cli.wait_for_service(timeout_sec=5.0)
    x_call = sim.position()[0]
    fut = cli.call_async(roszen.request_class("std_srvs/srv/Trigger")())
    sim.spin_until(fut.done, 30.0)  # the lockstep goes on while the service answers
    assert fut.result().success
    # the sim runs on (lockstep with the controller) while this process still has poses
    # queued, so the pose where the stop came is the controller's hold reference, not the last
    # pose this process has read: it lies ahead of the pose seen at the call, short of the goal
    sim.run_for(15.0)
    sim.node.spin_once(timeout_sec=0.1)
    assert sim.states[-1][0] == 2  # STOPPED
    x_stop = sim.refs[-1][0]                                   # the held pose
    assert x_call - 0.01 <= x_stop < 1.5, (x_call, x_stop)
    assert abs(sim.position()[0] - x_stop) < 0.1
    assert sim.position()[0] < 1.5


def test_bad_segment_rejected_node_keeps_holding(graph):
    p0 = np.array([1.0, 2.0, 3.0])
    sim = graph(p0, rot.IDENTITY)
    sim.commanded()
    seg = segment_msg(rest_to_rest(p0, p0 + 1.0, rot.IDENTITY, rot.IDENTITY, 5.0))
    seg.segment[3].pose.position.x = float("nan")
    sim.seg_pub.publish(seg)
    # bounded in sim time, not a fixed 3 s: on two loaded cores the rejection once came later
    sim.run_for(20.0, until=lambda: any("rejected" in e for _, e in sim.states))
    sim.run_for(1.0)
    sim.node.spin_once(timeout_sec=0.1)
    assert any("rejected" in e for _, e in sim.states), sim.states
    assert 9 not in [s for s, _ in sim.states]  # never CONTROLLING
    assert sim.states[-1][0] == 2  # still holding (STOPPED)
    assert np.linalg.norm(sim.position() - p0) < 1e-3
