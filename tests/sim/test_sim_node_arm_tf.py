"""The arm on /tf: the transforms sim_node publishes for the URDF's arm joints, chained from the
body pose, put every arm link where pybullet has it, so a viewer drawing /robot_description from
TF draws the whole robot."""
import numpy as np
import pytest

from astrobee import rotations as rot
from astrobee_sim.robot import ARM_LINKS, arm_transforms
from astrobee_sim.simulation import Simulation

roszen = pytest.importorskip("roszen")
from roszen import codec  # noqa: E402


def _compose(a, b):
    """Pose a (x, q) then the transform b (x, q): the child's world pose."""
    return a[0] + rot.rotate(a[1], b[0]), rot.multiply(a[1], b[1])


def _link_poses(sim, name=""):
    """World pose of every arm link from the body pose and the published transforms."""
    r = sim.robots[name]
    poses = {"body": r.pose()}
    for (parent, child), tr in zip(ARM_LINKS, arm_transforms(sim.arm_joints(name))):
        poses[child] = _compose(poses[parent], (np.array(tr[:3]), np.array(tr[3:])))
    return poses


@pytest.mark.parametrize("scenario", ["node2_to_jem", "node2_to_jem_bag"])
def test_arm_transforms_put_each_link_where_pybullet_has_it(scenario):
    """Stowed (no bag) or deployed and holding (bag), and while the arm moves and the robot
    turns: each link's frame within 1e-6 m and 1e-6 (pybullet's link states are float32-exact)
    of pybullet's own link frame."""
    with Simulation(scenario) as sim:
        r = sim.robots[""]
        p = sim.p
        for k in range(6):
            if k == 2:
                r.deploy_arm(scenario == "node2_to_jem")   # start a motion either way
                r.gripper(True)
            sim.command([0.1, 0.0, 0.0, 0.0, 0.0, 0.02])
            sim.step(40)
            got = _link_poses(sim)
            for link in ("arm_proximal", "arm_distal", "gripper", "finger_left", "finger_right"):
                ls = p.getLinkState(r.id, r.links[link], computeForwardKinematics=True,
                                    physicsClientId=sim.client)
                x, q = got[link]
                assert np.allclose(x, ls[4], atol=1e-6), (link, x, ls[4])
                assert abs(abs(float(np.dot(q, ls[5]))) - 1.0) < 1e-6, (link, q, ls[5])


class _Pub:
    def __init__(self, msg_type, topic, out):
        self.msg_type, self.topic_name, self._out = msg_type, topic, out
        self._ser = codec.msg_support(msg_type).serialize

    def publish(self, msg):
        self._out.append((self.topic_name, bytes(msg) if isinstance(msg, (bytes, bytearray))
                          else self._ser(msg)))


class _Node:
    def __init__(self):
        self.out = []

    def get_logger(self):
        class Log:
            def info(self, *a):
                pass
            warn = error = info
        return Log()

    def create_publisher(self, msg_type, topic, qos):
        return _Pub(msg_type, topic, self.out)

    def create_subscription(self, *a, **kw):
        return None

    create_service = create_subscription

    def destroy_node(self):
        pass


@pytest.mark.parametrize("backend", ["pybullet", "rigid"])
def test_sim_node_publishes_the_arm_frames_of_every_robot(backend):
    from astrobee.overrides import Overrides
    from astrobee_sim import sim_node
    from astrobee_sim.backend import make_backend
    opts = sim_node.SimOptions(backend, "two_robots_bag", Overrides(), 0, "fast", 350.0, 62.5, 10.0, 1.0,
                               30.0, 0.5, 0.0, False, False)
    node = _Node()
    s = sim_node.SimNode(node, make_backend(backend, "two_robots_bag", 0), opts)
    try:
        s.run_tick()
        names = s.names
    finally:
        s.close()
    tf = codec.msg_support("tf2_msgs/msg/TFMessage").deserialize
    last = [tf(d) for t, d in node.out if t == "/tf"][-1]
    pairs = {(t.header.frame_id, t.child_frame_id) for t in last.transforms}
    assert len(names) == 2
    for name in names:
        pre = f"{name}/" if name else ""
        assert ("world", f"{pre}body") in pairs
        assert {(pre + a, pre + b) for a, b in ARM_LINKS} <= pairs
    assert ("world", "bag") in pairs
    assert len(last.transforms) == len(names) * (1 + len(ARM_LINKS)) + 1
