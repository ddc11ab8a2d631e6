"""sim_node's per-tick shortcuts give what the slow paths gave: the compiled wall-clearance loop
(exact numpy distances, pybullet's closest points), the CDR templates of the per-tick messages
(byte-identical to serialising the message objects) and the in-place command decode."""
import math
import random

import numpy as np
import pytest

from astrobee_sim import world as world_mod
from astrobee_sim.world import station

roszen = pytest.importorskip("roszen")
from roszen import codec  # noqa: E402

from astrobee import msgconv as mc  # noqa: E402
from astrobee_sim import tick_wire  # noqa: E402


def _point_sets(w, rng, n_sets):
    """Robots (1 point), rigid bags (8 corners) and FEM-sized clouds near walls and in hatches."""
    for _ in range(n_sets):
        box = w.free[rng.integers(len(w.free))]
        centre = box[:3] + rng.random(3) * (box[3:] - box[:3])
        n = int(rng.choice([1, 8, 412]))
        yield centre + (rng.random((n, 3)) - 0.5) * rng.choice([0.0, 0.6, 3.0])


def test_compiled_clearance_equals_the_numpy_paths():
    """nearest() through the numba loop = brute force over every slab = the numpy path, exactly
    (same arithmetic), the index of the nearest point included."""
    if world_mod.min_sdf_kernel(load=True) is None:
        pytest.skip("numba not installed: nearest() is the numpy path")
    w = station(0.25)
    rng = np.random.default_rng(5)
    for pts in _point_sets(w, rng, 150):
        brute = w._box_sdf(pts, w.walls).min(axis=1)
        d, i = w.nearest(pts)
        assert d == brute.min() and brute[i] == d and i == int(brute.argmin())
        saved = world_mod._min_sdf
        world_mod._min_sdf = False                      # the numpy path
        try:
            assert w.nearest(pts) == (d, i)
        finally:
            world_mod._min_sdf = saved


def test_clearance_matches_pybullet_closest_points():
    """The distances against pybullet's own closest-point query on the same slabs: equal to
    1e-6 m where a wall face is nearest (Bullet's sphere-box test is exact there); where an
    edge is nearest Bullet's GJK answer is up to ~0.5 mm long, ours is the exact one."""
    import pybullet as p
    w = station(0.25)
    c = p.connect(p.DIRECT)
    try:
        ids = world_mod.build_pybullet(w, c, per_body=1)
        r = 1e-3
        probe = p.createMultiBody(baseMass=0, basePosition=[0, 0, 0], physicsClientId=c,
                                  baseCollisionShapeIndex=p.createCollisionShape(
                                      p.GEOM_SPHERE, radius=r, physicsClientId=c))
        rng = np.random.default_rng(7)
        faces = 0
        for _ in range(250):
            box = w.free[rng.integers(len(w.free))]
            q = box[:3] + rng.random(3) * (box[3:] - box[:3])
            ours = w.nearest(q[None])[0]
            if ours < 0.01:
                continue
            p.resetBasePositionAndOrientation(probe, q.tolist(), [0, 0, 0, 1], physicsClientId=c)
            p.performCollisionDetection(physicsClientId=c)
            theirs = min(cp[8] for b in ids
                         for cp in p.getClosestPoints(probe, b, 3.0, physicsClientId=c)) + r
            k = int(w._box_sdf(q[None], w.walls)[0].argmin())
            outside_axes = int((np.maximum(np.maximum(w.walls[k, :3] - q, q - w.walls[k, 3:]), 0)
                                > 0).sum())
            if outside_axes == 1:
                faces += 1
                assert abs(ours - theirs) < 1e-6, (q, ours, theirs)
            else:
                assert -1e-6 < theirs - ours < 1e-3, (q, ours, theirs)
        assert faces > 100
    finally:
        p.disconnect(physicsClientId=c)


def _layouts():
    """One message of each per-tick layout the sim publishes, with its changing fields."""
    M = roszen.message_class
    sf, vf, pf = tick_wire.stamp_fields, tick_wire.vec_fields, tick_wire.pose_fields
    ps = M("geometry_msgs/msg/PoseStamped")()
    ps.header.frame_id = "world"
    yield ps, sf() + pf("pose")
    tw = M("geometry_msgs/msg/TwistStamped")()
    tw.header.frame_id = "world"
    yield tw, sf() + vf("twist.linear") + vf("twist.angular")
    for child in ("body", "bumble/body"):
        ekf = M("astrobee_msgs/msg/EkfState")()
        ekf.header.frame_id, ekf.child_frame_id, ekf.confidence = "world", child, 0
        yield ekf, sf() + pf("pose") + vf("velocity") + vf("omega")
    yield M("rosgraph_msgs/msg/Clock")(), sf("clock")
    for n in (1, 2, 3):
        tf = M("tf2_msgs/msg/TFMessage")()
        ts = []
        for i in range(n):
            t = M("geometry_msgs/msg/TransformStamped")()
            t.header.frame_id, t.child_frame_id = "world", ("bag", "body", "honey/body")[i]
            ts.append(t)
        tf.transforms = ts
        yield tf, [f for i in range(n) for f in sf(f"transforms.{i}.header.stamp")
                   + vf(f"transforms.{i}.transform.translation")
                   + [(f"transforms.{i}.transform.rotation.{a}", "d") for a in "xyzw"]]
    for n, model in ((0, "rigid"), (1, "constraint"), (2, "fem"), (3, "composite")):
        bs = M("astrobee_msgs/msg/BagState")()
        bs.header.frame_id, bs.model, bs.variant = "world", model, "front" * n
        bs.attached = np.zeros(n, dtype=bool)
        yield bs, (sf() + pf("pose") + vf("velocity") + vf("omega") + [("deformation", "d")]
                   + [(f"attached.{k}", "?") for k in range(n)])
    cs = M("astrobee_msgs/msg/Contacts")()
    cs.header.frame_id = "world"
    yield cs, sf() + [("robot_clearance", "d"), ("bag_clearance", "d")]


def test_templates_are_byte_identical_to_the_serializer():
    rng = random.Random(3)
    for msg, fields in _layouts():
        ser = codec.msg_support(_type_of(msg)).serialize
        tpl = tick_wire.Template.build(msg, ser, fields)
        assert tpl is not None, fields[:3]
        for _ in range(50):
            vals = [tick_wire._random(f, rng) for _, f in fields]
            for (path, _), v in zip(fields, vals):
                tick_wire.set_field(msg, path, v)
            assert tpl.pack(vals) == ser(msg)


def _type_of(msg) -> str:
    for name in ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/TwistStamped",
                 "astrobee_msgs/msg/EkfState", "rosgraph_msgs/msg/Clock", "tf2_msgs/msg/TFMessage",
                 "astrobee_msgs/msg/BagState", "astrobee_msgs/msg/Contacts"):
        if type(msg) is roszen.message_class(name):
            return name
    raise KeyError(type(msg))


def test_a_template_that_cannot_be_located_is_refused():
    """A field given with the wrong format is not found in the bytes: no template (the sim then
    serialises the object), never wrong bytes."""
    ps = roszen.message_class("geometry_msgs/msg/PoseStamped")()
    ser = codec.msg_support("geometry_msgs/msg/PoseStamped").serialize
    assert tick_wire.Template.build(ps, ser, [("pose.position.x", "i")]) is None
    assert tick_wire.Template.build(ps, ser, [("pose.nothing", "d")]) is None
    assert ps.pose.position.x == 0.0


def test_command_decoded_in_place_equals_the_whole_message():
    from astrobee_sim.tick_wire import decode_command
    sup = codec.msg_support("astrobee_msgs/msg/FamCommand")
    rng = random.Random(0)
    for _ in range(500):
        m = sup.cls()
        m.header.frame_id = "".join(rng.choice("abé/_1") for _ in range(rng.randrange(0, 12)))
        m.header.stamp.sec = rng.randrange(-2**31, 2**31)
        m.header.stamp.nanosec = rng.randrange(0, 2**32)
        for f in ("force", "torque"):
            for a in "xyz":
                setattr(getattr(m.wrench, f), a, rng.choice([rng.uniform(-200, 200), math.inf,
                                                             math.nan, -0.0]))
        m.status, m.control_mode = rng.randrange(256), rng.randrange(256)
        data = sup.serialize(m)
        stamp, wrench = decode_command(data)
        ref = sup.deserialize(data)
        w = ref.wrench
        want = [w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z]
        assert stamp == mc.stamp_ns(ref.header.stamp)
        assert all(a == b or (math.isnan(a) and math.isnan(b)) for a, b in zip(wrench, want))
        # anything but the plain layout goes to the whole decoder (which raises when malformed)
        assert decode_command(data[:-1]) is None and decode_command(data + b"\0") is None
        assert decode_command(b"\x01\x00" + data[2:]) is None


class _Pub:
    def __init__(self, msg_type, topic, out):
        sup = codec.msg_support(msg_type)
        self.msg_type, self.topic_name, self._ser, self._out = sup.name, topic, sup.serialize, out

    def publish(self, msg):
        self._out.append((self.topic_name, bytes(msg) if isinstance(msg, (bytes, bytearray))
                          else self._ser(msg)))


class _Log:
    def info(self, *a):
        pass

    warn = error = info


class _Node:
    """The node calls SimNode makes, publishing into a list of (topic, CDR bytes)."""

    def __init__(self):
        self.out = []

    def get_logger(self):
        return _Log()

    def create_publisher(self, msg_type, topic, qos):
        return _Pub(msg_type, topic, self.out)

    def create_subscription(self, *a, **kw):
        return None

    def create_service(self, *a, **kw):
        return None

    def destroy_node(self):
        pass


def _sim_node(scenario, model, realism):
    from astrobee.overrides import Overrides
    from astrobee.scenario import Scenario
    from astrobee_sim import sim_node
    from astrobee_sim.backend import make_backend
    sc = Scenario.load(scenario)
    if model:
        sc = sc.override(bag_model=model)
    opts = sim_node.SimOptions("pybullet", scenario, Overrides(), 0, "fast", 350.0, 62.5, 10.0, 1.0, 30.0,
                               0.5, 0.0, False, False, realism=realism)
    kw = {}
    r = opts.realism_for(sc)
    if r is not None:
        sc = sc.override(realism=r)
        kw["realism"] = r
    node = _Node()
    return sim_node.SimNode(node, make_backend("pybullet", sc, 0, physics_rate=350.0, **kw), opts), node


@pytest.mark.parametrize("scenario,model,realism", [("node2_to_jem_bag", "rigid", "harsh"),
                                                    ("two_robots_bag", "", "")])
def test_sim_node_sends_the_bytes_the_message_objects_give(scenario, model, realism, monkeypatch):
    """The same run published through the templates and through the message objects: every
    message byte-identical, over flight, wall contacts and a watchdog fault (noisy EKF with
    `harsh`; two robots)."""
    runs = []
    for templates in (True, False):
        with monkeypatch.context() as mp:
            if not templates:                     # every layout refused: the message objects
                mp.setattr(tick_wire.Template, "build", classmethod(lambda *a, **k: None))
            s, node = _sim_node(scenario, model, realism)
            try:
                for k in range(900):              # up into the ceiling, then silence
                    if k < 840:
                        for n in s.names:
                            s.commands.command(n, s.now_ns(), [0.0, 0.0, 30.0, 0.0, 0.0, 0.0])
                    s.run_tick()
                tpls = s.state._templates
                assert tpls and all((t is not None) == templates for t in tpls.values())
            finally:
                s.close()
        runs.append(node.out)
    a, b = runs
    assert len(a) == len(b) > 900 * 7
    assert [t for t, _ in a] == [t for t, _ in b]
    assert all(x == y for x, y in zip(a, b))
    contacts = codec.msg_support("astrobee_msgs/msg/Contacts").deserialize
    assert any(contacts(d).in_contact for t, d in a if t == "/sim/contacts")
    assert any(t.endswith("/sim/fault") for t, _ in a)
