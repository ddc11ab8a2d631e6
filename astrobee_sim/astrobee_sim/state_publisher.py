"""sim_node's per-tick state: /clock, each robot's truth pose and twist, its EkfState and
propulsion fault, /tf (each robot's body and its arm's links, as robot_state_publisher would
from the joint states, and the bag), the cargo bag's state, mesh and surface marker, and
/sim/contacts.

The messages of a tick keep their layout from tick to tick, so each goes out as a CDR template
with its numbers packed in place (tick_wire: the same bytes as serialising the message objects,
checked when each layout is first built); a layout with no template is set on its message object
and serialised. The EKF carries the backend's estimate when the scenario's realism makes it noisy
(the truth topics stay truth); /sim/realism is republished when a disturbance pulse starts.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from astrobee import msgconv as mc

from . import markers, tick_wire
from .robot import ARM_LINKS, arm_transforms, qrot_floats

FAULT_WATCHDOG = 1
BAG_MARKER = "/sim/bag/marker"   # visualization_msgs/Marker TRIANGLE_LIST: the cargo bag's surface
# the numbers of the per-tick messages that change (tick_wire templates), in wire order
_POSE_FIELDS = tick_wire.stamp_fields() + tick_wire.pose_fields("pose")
_TWIST_FIELDS = (tick_wire.stamp_fields() + tick_wire.vec_fields("twist.linear")
                 + tick_wire.vec_fields("twist.angular"))
_EKF_FIELDS = (tick_wire.stamp_fields() + tick_wire.pose_fields("pose")
               + tick_wire.vec_fields("velocity") + tick_wire.vec_fields("omega"))
_BAG_FIELDS = (tick_wire.stamp_fields() + tick_wire.pose_fields("pose") + tick_wire.vec_fields("velocity")
               + tick_wire.vec_fields("omega") + [("deformation", "d")])
_CONTACTS_FIELDS = tick_wire.stamp_fields() + [("robot_clearance", "d"), ("bag_clearance", "d")]
_CLOCK_FIELDS = tick_wire.stamp_fields("clock")
MESSAGES = {
    "clock": "rosgraph_msgs/msg/Clock", "pose": "geometry_msgs/msg/PoseStamped",
    "twist": "geometry_msgs/msg/TwistStamped", "ekf": "astrobee_msgs/msg/EkfState",
    "tf": "tf2_msgs/msg/TFMessage", "tfs": "geometry_msgs/msg/TransformStamped",
    "bag": "astrobee_msgs/msg/BagState", "mesh": "astrobee_msgs/msg/BagMesh",
    "contacts": "astrobee_msgs/msg/Contacts", "contact": "astrobee_msgs/msg/Contact",
    "fault": "astrobee_msgs/msg/Fault"}


def frame(robot: str, link: str) -> str:
    """The TF frame of a robot's URDF link: the link's name, under the robot's namespace."""
    return f"{robot}/{link}" if robot else link


def _to_body(q: Any, v: list) -> tuple[float, float, float]:
    """A world vector in the body frame of q [x,y,z,w] (rotated by the conjugate)."""
    return qrot_floats((-q[0], -q[1], -q[2], q[3]), v)


def _tf_fields(n: int) -> list[tuple[str, str]]:
    """The changing numbers of a TFMessage of n transforms."""
    return [f for i in range(n) for f in
            tick_wire.stamp_fields(f"transforms.{i}.header.stamp") +
            tick_wire.vec_fields(f"transforms.{i}.transform.translation") +
            [(f"transforms.{i}.transform.rotation.{a}", "d") for a in "xyzw"]]


class StatePublisher:
    """The per-tick topics of sim_node (see the module docstring)."""

    def __init__(self, host: Any, mesh_rate: float) -> None:
        """host: the SimNode (node, sim, names, now_ns(), latched)."""
        from roszen import runtime as roszen
        self.host = host
        self.codec = roszen.codec
        n = host.node
        self.mesh_rate = mesh_rate
        self.M = {k: roszen.message_class(v) for k, v in MESSAGES.items()}
        self.pub_clock = n.create_publisher(MESSAGES["clock"], "/clock", roszen.CLOCK)
        self.pub_tf = n.create_publisher(MESSAGES["tf"], "/tf", 10)
        self.pub_bag = n.create_publisher(MESSAGES["bag"], mc.BAG_STATE, 10)
        self.pub_mesh = n.create_publisher(MESSAGES["mesh"], mc.BAG_MESH, 2)
        self.pub_contacts = n.create_publisher(MESSAGES["contacts"], mc.CONTACTS, 10)
        # a standard type any viewer shows (markers.py): the cargo bag's surface at the mesh rate
        self.pub_bag_marker = n.create_publisher("visualization_msgs/msg/Marker", BAG_MARKER, 2)
        self.bag_surface = markers.BagSurface(roszen.message_class("visualization_msgs/msg/Marker"),
                                              roszen.message_class("geometry_msgs/msg/Point"))
        self._marker_cdr = roszen.codec.msg_support("visualization_msgs/msg/Marker").serialize
        self.robot_io: dict[str, dict] = {}
        self._templates: dict = {}      # per-tick message layouts -> tick_wire.Template | None
        self._template_fields: dict = {}
        self._noisy_for: tuple = (None, False)    # (scenario, its EKF is noisy)
        self._ekf_state = getattr(host.sim, "ekf_state", host.sim.robot_state)
        self._arm_joints = getattr(host.sim, "arm_joints", None)     # None: no arm on /tf
        self._msgs = self._global_msgs()
        self._last_mesh = -1e9

    def add_robot(self, name: str) -> None:
        """The per-tick publishers of one robot (once per robot name)."""
        if name in self.robot_io:
            return
        n = self.host.node
        t = lambda rel: mc.robot_topic(name, rel)  # noqa: E731
        from roszen import runtime as roszen
        self.robot_io[name] = {
            "pose": n.create_publisher(MESSAGES["pose"], t(mc.POSE), 10),
            "twist": n.create_publisher(MESSAGES["twist"], t(mc.TWIST), 10),
            "ekf": n.create_publisher(MESSAGES["ekf"], t(mc.EKF), 10),
            "fault": n.create_publisher(MESSAGES["fault"], t(mc.FAULT), roszen.LATCHED),
            "fault_state": None, "msgs": self._robot_msgs(name)}

    def forget(self) -> None:
        """After a reset: faults are published afresh and the mesh goes out at the next tick."""
        for io in self.robot_io.values():
            io["fault_state"] = None
        self._last_mesh = -1e9

    def _robot_msgs(self, name: str) -> dict:
        """The per-tick messages of one robot, built once (publish() serialises at once, so
        mutating them afterwards is safe); headers, poses and rotations are shared objects."""
        M = self.M
        ps = M["pose"]()
        ps.header.frame_id = "world"
        tw = M["twist"]()
        tw.header = ps.header
        ekf = M["ekf"]()
        ekf.header = ps.header
        ekf.child_frame_id = f"{name}/body" if name else "body"
        ekf.pose = ps.pose
        ekf.confidence = mc.Confidence.GOOD
        ts = M["tfs"]()
        ts.header = ps.header
        ts.child_frame_id = ekf.child_frame_id
        ts.transform.rotation = ps.pose.orientation
        arm = []
        for parent, child in ARM_LINKS:
            t = M["tfs"]()
            t.header.frame_id, t.child_frame_id = frame(name, parent), frame(name, child)
            arm.append(t)
        return {"pose": ps, "twist": tw, "ekf": ekf, "tfs": ts, "arm": arm}

    def _global_msgs(self) -> dict:
        M = self.M
        bs = M["bag"]()
        bs.header.frame_id = "world"
        bts = M["tfs"]()
        bts.header = bs.header
        bts.child_frame_id = "bag"
        bts.transform.rotation = bs.pose.orientation
        cs = M["contacts"]()
        cs.header.frame_id = "world"
        return {"clock": M["clock"](), "tf": M["tf"](), "bag": bs, "bag_tfs": bts, "contacts": cs}

    def _send(self, pub: Any, key: Any, msg: Any, fields: Any, values: list) -> None:
        """Publish `msg` with `values` in its changing `fields` ((path, format) pairs, or a
        function making them): spliced into the layout's CDR template (tick_wire), or set on
        the object and serialised when the layout has no template."""
        tpl = self._templates.get(key, self)
        if tpl is self:                          # first time for this layout
            if callable(fields):
                fields = fields()
            tpl = self._templates[key] = tick_wire.Template.build(
                msg, self.codec.msg_support(pub.msg_type).serialize, fields)
            self._template_fields[key] = fields
        if tpl is not None:
            pub.publish(tpl.pack(values))
            return
        for (path, _), v in zip(self._template_fields[key], values):
            tick_wire.set_field(msg, path, v)
        pub.publish(msg)

    def publish_clock(self) -> None:
        """/clock alone (a paused start: sim time for late nodes and the recorder, no state)."""
        sec, nsec = divmod(self.host.now_ns(), 1_000_000_000)
        self._send(self.pub_clock, "clock", self._msgs["clock"], _CLOCK_FIELDS, [sec, nsec])

    def publish(self) -> None:
        """Every per-tick topic at the backend's current time."""
        host, sim = self.host, self.host.sim
        t = host.now_ns()
        sec, nsec = divmod(t, 1_000_000_000)
        g = self._msgs
        self._send(self.pub_clock, "clock", g["clock"], _CLOCK_FIELDS, [sec, nsec])
        tf_children: list = []
        tf_values: list = []
        positions = []
        sc = sim.scenario
        if sc is not self._noisy_for[0]:
            self._noisy_for = (sc, sc.realism.ekf_noisy)
        noisy = self._noisy_for[1]
        arm_joints = self._arm_joints
        for name in host.names:
            io = self.robot_io[name]
            msgs = io["msgs"]
            pos, q, v, w = sim.robot_state(name)
            positions.append(pos)
            p_, q_ = pos.tolist(), q.tolist()
            pose_values = [sec, nsec, *p_, *q_]
            self._send(io["pose"], ("pose", name), msgs["pose"], _POSE_FIELDS, pose_values)
            self._send(io["twist"], ("twist", name), msgs["twist"], _TWIST_FIELDS,
                       [sec, nsec, *v.tolist(), *w.tolist()])
            if noisy:                                # the estimate (the truth topics stay truth)
                pos_e, qe, v, w = self._ekf_state(name)
                ekf_pose = [*pos_e.tolist(), *qe.tolist()]
            else:
                qe, ekf_pose = q_, pose_values[2:]
            self._send(io["ekf"], ("ekf", name), msgs["ekf"], _EKF_FIELDS,
                       [sec, nsec, *ekf_pose, *v.tolist(), *_to_body(qe, w.tolist())])
            tf_children.append(msgs["tfs"])
            tf_values += pose_values
            if arm_joints is not None:
                tf_children += msgs["arm"]
                for tr in arm_transforms(arm_joints(name)):
                    tf_values += (sec, nsec, *tr)
            fault = sim.faulted(name)
            if fault != io["fault_state"]:
                io["fault_state"] = fault
                self._publish_fault(io["fault"], t, fault)
        info = sim.bag_info()
        rc, bc = sim.clearance(positions)
        if info is not None:
            self._publish_bag(info, t, sec, nsec, tf_children, tf_values)
        tf = g["tf"]
        key = ("tf", tuple(host.names), info is not None)
        if key not in self._templates:
            tf.transforms = tf_children
        self._send(self.pub_tf, key, tf, lambda: _tf_fields(len(tf_children)), tf_values)
        self._publish_contacts(t, sec, nsec, rc, bc)
        effects = getattr(sim, "effects", None)
        if effects is not None and len(effects.log) != host.latched.realism_applied:
            host.latched.publish_realism()

    def _publish_fault(self, pub: Any, t: int, fault: bool) -> None:
        """<ns>/sim/fault (latched): the propulsion watchdog's state, when it changes."""
        f = self.M["fault"]()
        mc.set_stamp_ns(f.header.stamp, t)
        f.header.frame_id = "world"
        f.source = "sim/propulsion_watchdog"
        f.code = FAULT_WATCHDOG
        f.active = bool(fault)
        f.message = (f"no command for {self.host.sim.watchdog_timeout:g} s: propulsion stopped"
                     if fault else "commands flowing")
        pub.publish(f)

    def _publish_bag(self, info: Any, t: int, sec: int, nsec: int, tf_children: list,
                     tf_values: list) -> None:
        """/sim/bag/state, the bag's /tf entry (appended) and, at the mesh rate, /sim/bag/mesh
        and the bag's surface marker."""
        sim, g = self.host.sim, self._msgs
        st = sim.bag_state()
        bs, bts = g["bag"], g["bag_tfs"]
        bs.model, bs.variant = info.model, info.variant
        bp, bq = st.position.tolist(), st.orientation.tolist()
        attached = [bool(a) for a in st.attached]
        if len(bs.attached) != len(attached):
            bs.attached = np.array(attached, dtype=bool)
        n = len(attached)
        self._send(self.pub_bag, ("bag", info.model, info.variant, n), bs,
                   lambda: _BAG_FIELDS + [(f"attached.{k}", "?") for k in range(n)],
                   [sec, nsec, *bp, *bq, *st.velocity.tolist(), *st.omega.tolist(),
                    float(st.deformation), *attached])
        tf_children.append(bts)
        tf_values += [sec, nsec, *bp, *bq]
        if sim.time - self._last_mesh >= 1.0 / self.mesh_rate - 1e-9:
            self._last_mesh = sim.time
            mc.set_stamp_ns(bs.header.stamp, t)
            pts = sim.bag_points()
            mm = self.M["mesh"]()
            mm.header = bs.header
            mm.num_nodes = len(pts)
            mm.positions = np.asarray(pts, np.float32).reshape(-1)
            self.pub_mesh.publish(mm)
            self.pub_bag_marker.publish(self.bag_surface.payload(        # CDR bytes
                getattr(sim, "bag", None), pts, bs.header, self._marker_cdr))

    def _publish_contacts(self, t: int, sec: int, nsec: int, rc: float, bc: float) -> None:
        """/sim/contacts: the clearances, and the contacts when there are some."""
        cs = self._msgs["contacts"]
        contacts = self.host.sim.contacts()
        if not contacts:
            if cs.contacts:
                cs.contacts, cs.in_contact = [], False
            self._send(self.pub_contacts, "contacts", cs, _CONTACTS_FIELDS,
                       [sec, nsec, float(rc), float(bc)])
            return
        lst = []
        for c in contacts:
            m = self.M["contact"]()
            m.body_a, m.body_b = c.body_a, c.body_b
            mc.set_vec(m.position, c.position)
            mc.set_vec(m.normal, c.normal)
            m.normal_force = float(c.normal_force)
            lst.append(m)
        cs.contacts = lst
        cs.in_contact = True
        mc.set_stamp_ns(cs.header.stamp, t)
        cs.robot_clearance, cs.bag_clearance = float(rc), float(bc)
        self.pub_contacts.publish(cs)
