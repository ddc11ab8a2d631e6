"""pd_controller_node: the PD tracker wired to the graph (thin layer over tracking.Tracker).

Subscribes <ns>/gnc/ekf (default; or loc/truth/pose + loc/truth/twist with state_source:=truth),
<ns>/gnc/ctl/segment (latched), <ns>/mob/flight_mode (latched), <ns>/sim/bag/state.
Publishes <ns>/gnc/ctl/command (FamCommand, BODY-frame wrench), <ns>/gnc/ctl/traj (the
reference, ControlState) and <ns>/mob/state (MotionState, latched, on change and at 1 Hz).
Service <ns>/gnc/ctl/stop (std_srvs/Trigger): hold the current pose.

One command per state sample, stamped with the state's stamp: at 62.5 Hz when the sim
publishes at 62.5 Hz, on sim time in every clock mode (in lockstep the sim waits for it).
"""
from __future__ import annotations

import sys
from typing import Any

import numpy as np

from astrobee import config, flight_modes
from roszen import node_main
from astrobee import rotations as rot

from . import mass as mp
from . import tracking as tk
from .pd import State
from .reference import from_control_states, time_of

LATCHED_DEPTH = 1
JUMP_DISTANCE = 0.5  # m between two state samples: a reset, not motion


def _vec(v: Any) -> np.ndarray:
    return np.array([v.x, v.y, v.z], dtype=float)


def _quat(q: Any) -> np.ndarray:
    return np.array([q.x, q.y, q.z, q.w], dtype=float)


def _set_vec(dst: Any, v: np.ndarray) -> None:
    dst.x, dst.y, dst.z = float(v[0]), float(v[1]), float(v[2])


def bag_figures(scenario: str, bag_mass: float, bag_size: list[float]) -> tuple[float, np.ndarray]:
    """Mass and size of the bag the robot may carry: parameters when set, else the scenario's,
    else config/bags.yaml's default."""
    default = config.bags()["default"]
    mass, size = float(default["mass"]), np.asarray(default["size"], float)
    if scenario:
        bag = config.scenario(scenario).get("bag") or {}
        mass = float(bag.get("mass", mass))
        size = np.asarray(bag.get("size", size), float)
    if bag_mass > 0:
        mass = bag_mass
    if len(bag_size) == 3 and all(s > 0 for s in bag_size):
        size = np.asarray(bag_size, float)
    return mass, size


class PdControllerNode:
    """Wiring of Tracker to topics; callbacks never raise (bad samples are logged and dropped)."""

    def __init__(self, argv: list[str] | None = None) -> None:
        import roszen
        from roszen import Durability, QoSProfile

        self.roszen = roszen
        self.node = roszen.Node("pd_controller_node", argv=argv)
        n = self.node
        self.log = n.get_logger()
        p = lambda name, default: n.declare_parameter(name, default).value  # noqa: E731
        self.state_source = p("state_source", "ekf")
        self.settle_time = float(p("settle_time", 5.0))
        hold_on_start = bool(p("hold_on_start", True))
        mode_name = p("flight_mode", "")
        scenario = p("scenario", "")
        bag_mass = float(p("bag_mass", -1.0))
        bag_size = list(p("bag_size", [0.0, 0.0, 0.0]))
        # omega of loc/truth/twist: "world" (as pybullet and ROS TwistStamped of a world pose)
        self.truth_omega_frame = p("truth_omega_frame", "world")
        p("rate", 62.5)          # informative: one command per state sample (62.5 Hz)
        p("stop_on_end", True)   # always: the end of a segment holds its final pose
        if not mode_name and scenario:
            mode_name = config.scenario(scenario).get("flight_mode", "")
        self.bag_mass, self.bag_size = bag_figures(scenario, bag_mass, bag_size)
        self.robot_mass = mp.robot()
        self.tracker = tk.Tracker(flight_modes.get(mode_name or None), self.robot_mass,
                                  settle_time=self.settle_time, hold_on_start=hold_on_start)
        self._carrying = False
        self._last_stamp: float | None = None
        self._last_state: State | None = None
        self._last_segment_stamp: tuple[int, int] | None = None
        self._pending_pose: dict[tuple[int, int], Any] = {}
        self._pending_twist: dict[tuple[int, int], Any] = {}
        self._last_mob_pub = -1e9

        latched = QoSProfile(depth=LATCHED_DEPTH, durability=Durability.TRANSIENT_LOCAL)
        self.FamCommand = roszen.message_class("astrobee_msgs/msg/FamCommand")
        self.ControlState = roszen.message_class("astrobee_msgs/msg/ControlState")
        self.MotionState = roszen.message_class("astrobee_msgs/msg/MotionState")
        self.pub_cmd = n.create_publisher("astrobee_msgs/msg/FamCommand", "gnc/ctl/command", 10)
        self.pub_traj = n.create_publisher("astrobee_msgs/msg/ControlState", "gnc/ctl/traj", 10)
        self.pub_mob = n.create_publisher("astrobee_msgs/msg/MotionState", "mob/state", latched)
        n.create_subscription("astrobee_msgs/msg/Segment", "gnc/ctl/segment", self._on_segment, latched)
        n.create_subscription("astrobee_msgs/msg/FlightMode", "mob/flight_mode", self._on_flight_mode,
                              latched)
        n.create_subscription("astrobee_msgs/msg/BagState", "sim/bag/state", self._on_bag, 10)
        if self.state_source == "truth":
            n.create_subscription("geometry_msgs/msg/PoseStamped", "loc/truth/pose", self._on_pose, 10)
            n.create_subscription("geometry_msgs/msg/TwistStamped", "loc/truth/twist", self._on_twist, 10)
        else:
            n.create_subscription("astrobee_msgs/msg/EkfState", "gnc/ekf", self._on_ekf, 10)
        self.Trigger = roszen.response_class("std_srvs/srv/Trigger")
        n.create_service("std_srvs/srv/Trigger", "gnc/ctl/stop", self._on_stop)
        self._publish_mob("", force=True)
        self.log.info(f"PD controller up: flight mode {self.tracker.flight_mode.name}, state from "
                      f"{self.state_source}, bag {self.bag_mass:.1f} kg when attached")

    # ---- inputs -----------------------------------------------------------------------
    def _on_segment(self, msg: Any) -> None:
        try:
            key = (int(msg.header.stamp.sec), int(msg.header.stamp.nanosec))
            if key == self._last_segment_stamp and key != (0, 0):
                return  # latched redelivery of the segment we already follow
            traj = from_control_states(msg.segment)
            if msg.flight_mode:
                self.tracker.set_flight_mode(flight_modes.get(msg.flight_mode))
        except (ValueError, AttributeError, TypeError) as exc:
            self.log.error(f"segment rejected: {exc}")
            self._publish_mob(f"segment rejected: {exc}", force=True)
            return
        self._last_segment_stamp = key
        now = self._last_stamp if self._last_stamp is not None else self._now()
        self.tracker.follow(traj, now)
        self.log.info(f"following a segment of {len(msg.segment)} states, {traj.duration:.1f} s")

    def _on_flight_mode(self, msg: Any) -> None:
        try:
            self.tracker.set_flight_mode(flight_modes.get(msg.name))
            self.log.info(f"flight mode {msg.name}")
        except flight_modes.UnknownFlightMode as exc:
            self.log.error(str(exc))

    def _on_bag(self, msg: Any) -> None:
        try:
            attached = bool(len(msg.attached)) and bool(np.any(np.asarray(msg.attached, bool)))
            state = self._last_state
            if not attached or state is None:
                if self._carrying:
                    self.tracker.set_mass(self.robot_mass)
                    self._carrying = False
                    self.log.info("bag released: robot mass only")
                return
            p_bag, q_bag = _vec(msg.pose.position), _quat(msg.pose.orientation)
            if not (np.all(np.isfinite(p_bag)) and np.all(np.isfinite(q_bag))):
                raise ValueError("non-finite bag pose")
            offset = rot.rotate_inverse(state.orientation, p_bag - state.position)
            r_rel = rot.to_matrix(state.orientation).T @ rot.to_matrix(q_bag)
            self.tracker.set_mass(mp.with_bag(self.robot_mass, self.bag_mass, self.bag_size,
                                              offset, r_rel))
            if not self._carrying:
                self.log.info(f"bag attached: {self.bag_mass:.1f} kg at "
                              f"{np.round(offset, 3).tolist()} m (body frame)")
            self._carrying = True
        except (ValueError, AttributeError, TypeError) as exc:
            self.log.warn(f"bad bag state dropped: {exc}")

    def _on_ekf(self, msg: Any) -> None:
        try:
            state = State(_vec(msg.pose.position), _vec(msg.velocity),
                          _quat(msg.pose.orientation), _vec(msg.omega))
        except (AttributeError, TypeError) as exc:
            self.log.warn(f"bad EKF state dropped: {exc}")
            return
        self._control(state, msg.header.stamp)

    def _on_pose(self, msg: Any) -> None:
        self._pair(msg, self._pending_pose, self._pending_twist, pose_first=True)

    def _on_twist(self, msg: Any) -> None:
        self._pair(msg, self._pending_twist, self._pending_pose, pose_first=False)

    def _pair(self, msg: Any, mine: dict, other: dict, pose_first: bool) -> None:
        key = (int(msg.header.stamp.sec), int(msg.header.stamp.nanosec))
        if key in other:
            peer = other.pop(key)
            pose, twist = (msg, peer) if pose_first else (peer, msg)
            for old in [k for k in other if k < key]:
                del other[old]
            for old in [k for k in mine if k < key]:
                del mine[old]
            try:
                q = _quat(pose.pose.orientation)
                omega = _vec(twist.twist.angular)
                if self.truth_omega_frame == "world":
                    omega = rot.rotate_inverse(q, omega)
                state = State(_vec(pose.pose.position), _vec(twist.twist.linear), q, omega)
            except (AttributeError, TypeError, ValueError) as exc:
                self.log.warn(f"bad truth state dropped: {exc}")
                return
            self._control(state, pose.header.stamp)
        else:
            mine[key] = msg
            if len(mine) > 20:
                del mine[min(mine)]

    def _on_stop(self, req: Any) -> Any:
        resp = self.Trigger()
        if self._last_state is None:
            resp.success, resp.message = False, "no state received yet: nothing to stop"
            return resp
        self.tracker.stop(self._last_state, self._last_stamp or 0.0)
        resp.success, resp.message = True, "stopping: holding the current pose"
        self.log.info("stop requested")
        return resp

    # ---- control ----------------------------------------------------------------------
    def _now(self) -> float:
        return self.node.get_clock().now().nanoseconds * 1e-9

    def _control(self, state: State, stamp: Any) -> None:
        vals = np.concatenate([state.position, state.velocity, state.orientation, state.omega])
        if not np.all(np.isfinite(vals)) or np.linalg.norm(state.orientation) < 1e-6:
            self.log.warn("non-finite state dropped")
            return
        state.orientation = rot.normalize(state.orientation)
        t = time_of(stamp)
        last = self._last_state
        if last is not None and self._last_stamp is not None and (
                t < self._last_stamp - 1e-6
                or float(np.linalg.norm(state.position - last.position)) > JUMP_DISTANCE):
            self.tracker.rehold(state, "state jumped (simulation reset?): holding the new pose")
            self._last_segment_stamp = None
        dt = 1.0 / 62.5 if self._last_stamp is None else min(max(t - self._last_stamp, 0.0), 0.1)
        self._last_stamp, self._last_state = t, state
        step = self.tracker.update(state, t, dt)
        self._publish_command(step, stamp)
        self._publish_traj(step, stamp)
        self._publish_mob(step.event, force=bool(step.event))

    def _publish_command(self, step: tk.Step, stamp: Any) -> None:
        out = step.output
        m = self.FamCommand()
        m.header.stamp = stamp
        m.header.frame_id = "body"
        _set_vec(m.wrench.force, out.force)
        _set_vec(m.wrench.torque, out.torque)
        _set_vec(m.accel, out.accel)
        _set_vec(m.alpha, out.alpha)
        m.status = 3 if out.saturated else 0
        _set_vec(m.position_error, out.position_error)
        _set_vec(m.position_error_integrated, out.position_error_integrated)
        _set_vec(m.attitude_error, out.attitude_error)
        _set_vec(m.attitude_error_integrated, out.attitude_error_integrated)
        m.attitude_error_mag = out.attitude_error_mag
        m.control_mode = step.control_mode
        self.pub_cmd.publish(m)

    def _publish_traj(self, step: tk.Step, stamp: Any) -> None:
        ref = step.reference
        m = self.ControlState()
        m.when = stamp
        _set_vec(m.pose.position, ref.position)
        q = ref.orientation
        m.pose.orientation.x, m.pose.orientation.y = float(q[0]), float(q[1])
        m.pose.orientation.z, m.pose.orientation.w = float(q[2]), float(q[3])
        _set_vec(m.twist.linear, ref.velocity)
        _set_vec(m.twist.angular, ref.omega)
        _set_vec(m.accel.linear, ref.accel)
        _set_vec(m.accel.angular, ref.alpha)
        self.pub_traj.publish(m)

    def _publish_mob(self, event: str, force: bool = False) -> None:
        t = self._last_stamp if self._last_stamp is not None else 0.0
        if not force and t - self._last_mob_pub < 1.0:
            return
        self._last_mob_pub = t
        m = self.MotionState()
        if self._last_stamp is not None:
            m.header.stamp.sec = int(t)
            m.header.stamp.nanosec = int(round((t - int(t)) * 1e9)) % 1_000_000_000
        m.state = self.tracker.state
        m.fsm_event = event or self.tracker.segment_result
        m.fsm_state = tk.STATE_NAMES.get(self.tracker.state, str(self.tracker.state))
        if self.tracker.segment_result:
            m.fsm_state += f" {self.tracker.segment_result}"
        self.pub_mob.publish(m)
        if event:
            self.log.info(f"{m.fsm_state}: {event}")


def main(argv: list[str] | None = None) -> int:
    """Entry point (`ros2 run astrobee_control pd_controller_node`)."""
    return node_main.run(PdControllerNode, argv)


if __name__ == "__main__":
    sys.exit(main())
