"""sim_node's latched topics: what the world is, published at start and after every reset.

/sim/scenario (ScenarioInfo: the scenario as built, for the controller and the mission),
each robot's <ns>/mob/flight_mode, /sim/realism (the knobs, the pulse schedule and the pulses
applied), and for any viewer /sim/markers (keep-in boxes, module labels), /sim/robot_markers
(each robot's boxes in its body frame) and /robot_description (the Astrobee URDF; its links'
transforms go on /tf with each tick's state).
"""
from __future__ import annotations

from typing import Any

import yaml

from astrobee import config
from astrobee import msgconv as mc
from astrobee.scenario import Scenario

from . import markers
from .world import module_colour

ROBOT_MARKERS = "/sim/robot_markers"   # latched MarkerArray: each robot's boxes in its body frame
SIM_REALISM = "/sim/realism"    # latched std_msgs/String: the realism in effect, pulses applied
MESSAGES = {
    "markers": "visualization_msgs/msg/MarkerArray", "marker": "visualization_msgs/msg/Marker",
    "mode": "astrobee_msgs/msg/FlightMode", "scenario": "astrobee_msgs/msg/ScenarioInfo",
    "pose_": "geometry_msgs/msg/Pose", "string": "std_msgs/msg/String"}


class LatchedTopics:
    """The latched publishers of sim_node (see the module docstring)."""

    def __init__(self, host: Any) -> None:
        """host: the SimNode (node, sim, names, now_ns())."""
        from roszen import runtime as roszen
        from roszen.runtime import LATCHED
        self.host = host
        n = host.node
        self.M = {k: roszen.message_class(v) for k, v in MESSAGES.items()}
        self.pub_markers = n.create_publisher(MESSAGES["markers"], mc.MARKERS, LATCHED)
        self.pub_scenario = n.create_publisher(MESSAGES["scenario"], mc.SIM_SCENARIO, LATCHED)
        self.pub_realism = n.create_publisher(MESSAGES["string"], SIM_REALISM, LATCHED)
        self.pub_robot_description = n.create_publisher(MESSAGES["string"], "/robot_description",
                                                        LATCHED)
        self.pub_robot_markers = n.create_publisher(MESSAGES["markers"], ROBOT_MARKERS, LATCHED)
        self.pub_mode: dict[str, Any] = {}
        self.realism_applied = -1      # pulses in the last /sim/realism

    def add_robot(self, name: str) -> None:
        """A robot's latched flight-mode publisher (once per robot name)."""
        if name not in self.pub_mode:
            from roszen import runtime as roszen
            self.pub_mode[name] = self.host.node.create_publisher(
                MESSAGES["mode"], mc.robot_topic(name, mc.FLIGHT_MODE), roszen.LATCHED)

    def publish_modes(self) -> None:
        """<ns>/mob/flight_mode of every robot: the backend's current flight modes."""
        host = self.host
        for name in host.names:
            m, fm = self.M["mode"](), host.sim.flight_mode_of(name)
            mc.set_stamp_ns(m.header.stamp, host.now_ns())
            m.name, m.control_enabled, m.speed = fm.name, fm.control_enabled, fm.speed
            m.collision_radius = fm.collision_radius
            m.tolerance_pos = m.tolerance_pos_endpoint = fm.tolerance_pos
            m.tolerance_att = fm.tolerance_att
            for k in ("att_kp", "att_ki", "omega_kd", "pos_kp", "pos_ki", "vel_kd"):
                mc.set_vec(getattr(m, k), getattr(fm, k))
            m.hard_limit_vel, m.hard_limit_accel = fm.hard_limit_vel, fm.hard_limit_accel
            m.hard_limit_omega, m.hard_limit_alpha = fm.hard_limit_omega, fm.hard_limit_alpha
            self.pub_mode[name].publish(m)

    def publish_scenario(self) -> None:
        """/sim/scenario: the scenario as built (overrides applied), for the controller and the
        mission (they read the bag and the goal from here, not from config files)."""
        sim = self.host.sim
        sc: Scenario = sim.scenario
        m = self.M["scenario"]()
        mc.set_stamp_ns(m.header.stamp, self.host.now_ns())
        m.header.frame_id = "world"
        m.name, m.description = sc.name, sc.description
        m.seed = int(sim.seed)
        m.flight_mode = sc.flight_mode
        m.robots = [r.name for r in sc.robots]
        starts = []
        for r in sc.robots:
            ps = self.M["pose_"]()
            mc.set_pose(ps, r.position, r.orientation)
            starts.append(ps)
        m.starts = starts
        m.has_goal = sc.goal_position is not None
        if m.has_goal:
            mc.set_pose(m.goal, sc.goal_position, sc.goal_orientation)
        else:
            m.goal.orientation.w = 1.0
        m.face_forward = bool(sc.face_forward)
        m.carrying_bag = sc.bag is not None
        info = sim.bag_info()
        if sc.bag is not None:
            m.bag_model, m.bag_variant = sc.bag.model, sc.bag.variant
            m.bag_solver = sc.bag.solver if sc.bag.model == "fem" else ""
            told = getattr(sim, "told_bag_mass", None)
            m.bag_mass = float(told() if told is not None else sc.realism.told_mass(sc.bag.mass))
            m.bag_mass_true = float(sc.bag.mass)
            mc.set_vec(m.bag_size, sc.bag.size)
            m.bag_nodes = int(info.nodes) if info is not None else 0
        m.carry_extent = float(sc.carry_extent)
        m.realism = yaml.safe_dump(sc.realism.changed(), sort_keys=False)
        m.yaml = sc.to_yaml()
        self.pub_scenario.publish(m)

    def publish_realism(self) -> None:
        """/sim/realism: the knobs in effect, the pulse schedule and the pulses applied
        (republished by the state publisher when a pulse starts)."""
        sim = self.host.sim
        sched = getattr(sim, "disturbance_schedule", None)
        applied = list(getattr(sim, "disturbance_log", []))
        m = self.M["string"]()
        m.data = yaml.safe_dump({"knobs": sim.scenario.realism.changed(),
                                 "schedule": sched() if sched is not None else [],
                                 "applied": applied}, sort_keys=False)
        self.pub_realism.publish(m)
        self.realism_applied = len(applied)

    def publish_markers(self) -> None:
        """/sim/markers (keep-in boxes, module labels), /sim/robot_markers, /robot_description."""
        M = self.M
        arr = M["markers"]()
        out = []
        w = self.host.sim.world
        for i, (box, mod) in enumerate(zip(w.keep_in, w.modules)):
            m = M["marker"]()
            m.header.frame_id = "world"
            m.ns, m.id, m.type, m.action = "keep_in", i, 1, 0           # CUBE, ADD
            mc.set_vec(m.pose.position, (box[:3] + box[3:]) / 2)
            m.pose.orientation.w = 1.0
            mc.set_vec(m.scale, box[3:] - box[:3])
            m.color.r, m.color.g, m.color.b = module_colour(mod)
            m.color.a = 0.15
            out.append(m)
        for i, (name, mod) in enumerate(config.iss()["modules"].items()):
            m = M["marker"]()
            m.header.frame_id = "world"
            m.ns, m.id, m.type, m.action = "modules", i, 9, 0           # TEXT_VIEW_FACING
            mc.set_vec(m.pose.position, mod["origin"])
            m.pose.orientation.w = 1.0
            m.scale.z = 0.2
            m.color.r = m.color.g = m.color.b = m.color.a = 1.0
            m.text = mod.get("label", name)
            out.append(m)
        arr.markers = out
        self.pub_markers.publish(arr)
        robots = M["markers"]()             # robot boxes in each body frame (TF)
        robots.markers = [m for k, name in enumerate(self.host.names) for m in markers.robot_markers(
            M["marker"], f"{name}/body" if name else "body", 3 * k)]
        self.pub_robot_markers.publish(robots)
        desc = M["string"]()
        desc.data = markers.robot_description()
        self.pub_robot_description.publish(desc)
