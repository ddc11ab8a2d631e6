"""The leg's plan from planner_node: PlanGlobal for one robot, PlanFormation for two holding
the cargo bag; the segments stamped to start at one time (a fixed sim time in deterministic
lockstep)."""
from __future__ import annotations

from typing import Any

import numpy as np

from astrobee import msgconv as mc

from .result import LegResult, MissionError
from .watch import RobotWatch

# Formation segments start this far (sim s) after the request: every controller has its
# segment before the common start stamp, so the robots start together.
FORMATION_LEAD = 0.5
# Deterministic runs: the segments start this long (sim s) after the reset's t=0 (the sim is
# paused until every controller holds its segment; the lead lets each controller hold the start
# with the cargo bag observed and a freshly built bag settle a moment, as a mission planning
# in a running sim had).
HANDOVER_LEAD = 1.0


def plan_one(client: Any, w: RobotWatch, info: Any, fm: Any, goal_p: np.ndarray,
             goal_q: np.ndarray, res: LegResult) -> tuple[list[Any], float]:
    """PlanGlobal for one robot: ([segment], duration)."""
    pos, q = w.pose
    req = client.roszen.request_class("astrobee_msgs/srv/PlanGlobal")()
    set_pose(req.start, pos, q)
    set_pose(req.goal, goal_p, goal_q)
    req.flight_mode = fm.name
    req.face_forward = bool(info.face_forward)
    # the cargo bag trails along the path: the scenario's margin (bags.yaml's carry_extent default)
    req.carry_extent = float(info.carry_extent) if info.carrying_bag else 0.0
    res.carry_extent = req.carry_extent
    plan = _call_planner(client, client.planner, req, mc.PLANNER_GLOBAL, "planning", res)
    client.log.info(f"{info.name}: plan of {plan.duration:.1f} s in {plan.planning_time:.2f} s, "
                    f"{len(plan.segment)} states")
    seg = client.roszen.message_class("astrobee_msgs/msg/Segment")()
    seg.header.stamp = client.node.get_clock().now().to_msg()
    seg.header.frame_id = "world"
    seg.flight_mode = fm.name
    seg.segment = list(plan.segment)
    if client.handover:        # starts at a fixed sim time (the plan's times start at 0)
        t0 = client.sim_time + HANDOVER_LEAD
        for s in seg.segment:
            mc.set_stamp_ns(s.when, mc.stamp_ns(s.when) + mc.to_ns(t0))
        mc.set_stamp(seg.header.stamp, t0)
    return [seg], float(plan.duration)


def plan_formation(client: Any, ws: list[RobotWatch], info: Any, fm: Any, goal_p: np.ndarray,
                   goal_q: np.ndarray, res: LegResult) -> tuple[list[Any], float]:
    """PlanFormation for two robots holding the cargo bag: (one segment per robot, all with
    the same start stamp a moment ahead, duration)."""
    req = client.roszen.request_class("astrobee_msgs/srv/PlanFormation")()
    req.robots = [w.name for w in ws]
    poses = []
    for w in ws:
        m = client.roszen.message_class("geometry_msgs/msg/Pose")()
        set_pose(m, *w.pose)
        poses.append(m)
    req.starts = poses
    set_pose(req.goal, goal_p, goal_q)
    if info.carrying_bag and client.cargo_state is not None:
        req.has_bag_pose = True
        req.bag_pose = client.cargo_state.pose
        req.bag_size = info.bag_size
    req.flight_mode = fm.name
    t_start = client.sim_time + (HANDOVER_LEAD if client.handover else FORMATION_LEAD)
    mc.set_stamp(req.start_time, t_start)
    plan = _call_planner(client, client.formation, req, mc.PLANNER_FORMATION,
                         "formation planning", res)
    client.log.info(f"{info.name}: formation plan of {plan.duration:.1f} s in "
                    f"{plan.planning_time:.2f} s: {'; '.join(plan.steps)}")
    for w, seg in zip(ws, plan.segments):
        end = seg.segment[-1].pose
        client._goals[w.name] = mc.pose(end)
    return list(plan.segments), float(plan.duration)


def _call_planner(client: Any, service: Any, req: Any, name: str, what: str,
                  res: LegResult) -> Any:
    """A planner service's answer (120 s at most), its planning time noted in `res`; a failed
    plan ends the leg with a MissionError naming `what`, the code and the planner's message."""
    plan = client.call(service, req, 120.0, name)
    res.planning_time = float(plan.planning_time)
    if not plan.success:
        raise MissionError(f"{what} failed (code {plan.code}): {plan.message}")
    return plan


def set_pose(dst: Any, p: np.ndarray, q: np.ndarray) -> None:
    """A geometry_msgs/Pose from a position and an [x, y, z, w] quaternion."""
    dst.position.x, dst.position.y, dst.position.z = (float(v) for v in p)
    dst.orientation.x, dst.orientation.y, dst.orientation.z, dst.orientation.w = (float(v) for v in q)
