"""planner_node: /mob/planner/global, /mob/planner/local and /mob/planner/formation services,
/mob/planner/path (latched).

Thin wiring over planner.plan_global, local_planner.plan and multi_robot.plan_formation (two
robots carrying one bag: one segment per robot); bad requests get a failure response
with an Astrobee Motion result code and a message, and the node keeps serving.
Parameters: sample_rate (Hz, default 10), flight_mode (default when a request names none and
no /mob/flight_mode was received).
"""
from __future__ import annotations

import sys
import time
import traceback
from typing import Any

import numpy as np

from roszen import runtime as roszen
from roszen.runtime import Durability, QoSProfile

from astrobee import config, flight_modes
from astrobee import msgconv as mc
from roszen.runtime import node_main
from roszen.parameters import runtime

from . import conversions as cv
from . import local_planner, multi_robot, planner, trajectory
from .errors import OutsideSafeSet, PlanError
from .planner import INVALID_COMMAND, PLAN_FAILED, SUCCESS, VIOLATES_KEEP_IN


class PlannerNode:
    def __init__(self, argv: list[str] | None = None):
        self.node = roszen.Node("planner_node", argv=argv)
        self.log = self.node.get_logger()
        # both applied at run time (`param set`): the next request uses the new value
        self.sample_rate = float(self.node.declare_parameter("sample_rate", 10.0, runtime(
            lambda v: setattr(self, "sample_rate", float(v)), min_value=1e-3, max_value=1000.0)).value)
        self.default_mode = str(self.node.declare_parameter(
            "flight_mode", config.astrobee()["default_flight_mode"],
            runtime(lambda v: setattr(self, "default_mode", str(v)),
                    choices=flight_modes.names())).value)
        self.current_mode: str | None = None
        self.ControlState = roszen.message_class("astrobee_msgs/msg/ControlState")
        self.BezierCurve = roszen.message_class("astrobee_msgs/msg/BezierCurve")
        self.QuatPoly = roszen.message_class("astrobee_msgs/msg/QuaternionPolynomial")
        self.Point = roszen.message_class("geometry_msgs/msg/Point")
        self.Path = roszen.message_class("nav_msgs/msg/Path")
        self.PoseStamped = roszen.message_class("geometry_msgs/msg/PoseStamped")
        self.GlobalResp = roszen.response_class("astrobee_msgs/srv/PlanGlobal")
        self.LocalResp = roszen.response_class("astrobee_msgs/srv/PlanLocal")
        self.FormationResp = roszen.response_class("astrobee_msgs/srv/PlanFormation")
        self.Segment = roszen.message_class("astrobee_msgs/msg/Segment")
        latched = QoSProfile(depth=1, durability=Durability.TRANSIENT_LOCAL)
        # relative names: `-r __ns:=/bumble` moves them as it moves every other node's
        self.path_pub = self.node.create_publisher("nav_msgs/msg/Path", "mob/planner/path", latched)
        self.node.create_subscription("astrobee_msgs/msg/FlightMode", "mob/flight_mode",
                                      self._on_flight_mode, latched)
        self.node.create_service("astrobee_msgs/srv/PlanGlobal", mc.PLANNER_GLOBAL.lstrip("/"),
                                 self._global)
        self.node.create_service("astrobee_msgs/srv/PlanLocal", mc.PLANNER_LOCAL.lstrip("/"),
                                 self._local)
        self.node.create_service("astrobee_msgs/srv/PlanFormation",
                                 mc.PLANNER_FORMATION.lstrip("/"), self._formation)
        planner.cached_safe_set(0.0)      # build the safe set before the first request
        self.log.info(f"planner ready (sample rate {self.sample_rate} Hz, "
                      f"default flight mode {self.default_mode})")

    def _on_flight_mode(self, msg: Any) -> None:
        name = str(getattr(msg, "name", ""))
        if not name:
            return
        if name not in flight_modes.names():   # a stray publisher must not break every plan
            if self.current_mode != name and not getattr(self, "_warned_mode", False):
                self.log.warning(f"ignoring unknown flight mode {name[:40]!r} on /mob/flight_mode")
                self._warned_mode = True
            return
        self.current_mode = name

    def _rate(self, requested: float) -> float:
        r = float(requested)
        if not np.isfinite(r) or r < 0:
            raise PlanError(INVALID_COMMAND, f"sample_rate must be >= 0 (got {requested})")
        r = r if r > 0 else self.sample_rate
        return min(r, 1000.0)

    # ---- /mob/planner/global -----------------------------------------------------------
    def _global(self, req: Any) -> Any:
        resp = self.GlobalResp()
        t0 = time.perf_counter()
        try:
            rate = self._rate(req.sample_rate)
            p0, q0 = cv.pose_to_arrays(req.start)
            p1, q1 = cv.pose_to_arrays(req.goal)
            mode = req.flight_mode or self.current_mode or self.default_mode
            plan = planner.plan_global(p0, q0, p1, q1, mode, bool(req.face_forward),
                                       float(req.carry_extent))
            traj = plan.trajectory
            try:
                states = traj.sample_rate(rate, max_states=trajectory.MAX_STATES)
            except ValueError as exc:
                raise PlanError(INVALID_COMMAND, str(exc)) from exc
            resp.segment = cv.states_to_msgs(states, self.ControlState)
            resp.position_spline = [cv.bezier_to_msg(p, self.BezierCurve, self.Point)
                                    for p in traj.position]
            resp.attitude_spline = [cv.quatpoly_to_msg(a, self.QuatPoly) for a in traj.attitude]
            resp.duration = traj.duration
            resp.success = True
            resp.code = plan.code
            resp.message = ("already there" if plan.code != SUCCESS else
                            f"{len(plan.route)} boxes, {traj.duration:.1f} s")
            self._publish_path(states)
        except PlanError as exc:
            resp.success, resp.code, resp.message = False, exc.code, str(exc)
        except Exception as exc:  # a bug must not take the node down
            self.log.error(f"global planner crashed: {exc}\n{traceback.format_exc()}")
            resp.success, resp.code, resp.message = False, PLAN_FAILED, f"internal error: {exc}"
        resp.planning_time = time.perf_counter() - t0
        self.log.info(f"global plan: code {resp.code}, {resp.message} "
                      f"({resp.planning_time:.3f} s)")
        return resp

    def _publish_path(self, states) -> None:
        msg = self.Path()
        msg.header.frame_id = "world"
        msg.header.stamp = self.node.get_clock().now().to_msg()
        poses = []
        for i in range(len(states)):
            ps = self.PoseStamped()
            ps.header.frame_id = "world"
            cv.set_time(ps.header.stamp, float(states.t[i]))
            cv.set_pose(ps.pose, states.pos[i], states.quat[i])
            poses.append(ps)
        msg.poses = poses
        self.path_pub.publish(msg)

    # ---- /mob/planner/formation --------------------------------------------------------
    def _formation(self, req: Any) -> Any:
        resp = self.FormationResp()
        t0 = time.perf_counter()
        try:
            rate = self._rate(req.sample_rate)
            names = [str(n) for n in req.robots]
            if len(names) != len(req.starts):
                raise PlanError(INVALID_COMMAND, f"{len(names)} robot names but {len(req.starts)} "
                                                 f"start poses")
            if len(set(names)) != len(names):
                raise PlanError(INVALID_COMMAND, f"robot names must differ, got {names}")
            starts = [cv.pose_to_arrays(s) for s in req.starts]
            goal = cv.pose_to_arrays(req.goal)
            bag_pose = cv.pose_to_arrays(req.bag_pose) if req.has_bag_pose else None
            size = [req.bag_size.x, req.bag_size.y, req.bag_size.z]
            mode = req.flight_mode or self.current_mode or self.default_mode
            plan = multi_robot.plan_formation(starts, goal, bag_pose,
                                              None if not any(size) else size, mode)
            t_start = cv.time_of(req.start_time)
            per_robot = trajectory.MAX_STATES // len(plan.robots)   # the cap is per response
            try:
                samples = [traj.sample_rate(rate, max_states=per_robot) for traj in plan.robots]
            except ValueError as exc:
                raise PlanError(INVALID_COMMAND, str(exc)) from exc
            segs = []
            for traj, states in zip(plan.robots, samples):
                seg = self.Segment()
                seg.header.frame_id = "world"
                cv.set_time(seg.header.stamp, t_start)
                seg.flight_mode = str(plan.formation.centre.trajectory.info.get("flight_mode", mode))
                seg.segment = cv.states_to_msgs(states, self.ControlState, t_start)
                segs.append(seg)
            resp.robots, resp.segments = names, segs
            resp.steps = list(plan.formation.steps)
            resp.duration = plan.formation.centre.trajectory.duration
            resp.success, resp.code = True, SUCCESS
            resp.message = (f"{len(names)} robots, {len(plan.formation.steps)} steps, "
                            f"{resp.duration:.1f} s")
        except PlanError as exc:
            resp.success, resp.code, resp.message = False, exc.code, str(exc)
        except Exception as exc:  # a bug must not take the node down
            self.log.error(f"formation planner crashed: {exc}\n{traceback.format_exc()}")
            resp.success, resp.code, resp.message = False, PLAN_FAILED, f"internal error: {exc}"
        resp.planning_time = time.perf_counter() - t0
        self.log.info(f"formation plan: code {resp.code}, {resp.message} "
                      f"({resp.planning_time:.3f} s)")
        return resp

    # ---- /mob/planner/local ------------------------------------------------------------
    def _local(self, req: Any) -> Any:
        resp = self.LocalResp()
        t0 = time.perf_counter()
        try:
            rate = self._rate(req.sample_rate)
            start = cv.control_state_to_dict(req.start)
            goal = cv.control_state_to_dict(req.goal)
            try:     # bounded: duration, states, keep-in, the flight mode's limits
                traj = local_planner.plan_within_limits(start, goal, float(req.duration),
                                                        self.current_mode or self.default_mode)
                trajectory.check_sample_count(traj.duration, rate)
            except OutsideSafeSet as exc:
                raise PlanError(VIOLATES_KEEP_IN, str(exc)) from exc
            except ValueError as exc:
                raise PlanError(INVALID_COMMAND, str(exc)) from exc
            t_start = cv.time_of(req.start.when)
            resp.segment = cv.states_to_msgs(traj.sample_rate(rate), self.ControlState, t_start)
            resp.position = cv.bezier_to_msg(traj.position[0], self.BezierCurve, self.Point)
            resp.attitude = cv.quatpoly_to_msg(traj.attitude[0], self.QuatPoly)
            resp.success, resp.code, resp.message = True, SUCCESS, "ok"
        except PlanError as exc:
            resp.success, resp.code, resp.message = False, exc.code, str(exc)
        except Exception as exc:
            self.log.error(f"local planner crashed: {exc}\n{traceback.format_exc()}")
            resp.success, resp.code, resp.message = False, PLAN_FAILED, f"internal error: {exc}"
        resp.planning_time = time.perf_counter() - t0
        return resp


def main(argv: list[str] | None = None) -> int:
    """Entry point (`ros2 run astrobee_planning planner_node`)."""
    return node_main.run(PlannerNode, argv)


if __name__ == "__main__":
    sys.exit(main())
