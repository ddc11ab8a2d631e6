"""The ROS edge in one place: message <-> numpy, time stamps with one rule, message constants by
name and the topic names of the graph. Attribute access only (messages are duck-typed), so
this module imports no transport and works on roszen, rosbags or rclpy message objects.

Stamp rule: t seconds -> nanoseconds rounded once, then divmod: never a nanosec of 1e9, never
time going back across a second boundary; negative times clamp to 0.
"""
from __future__ import annotations

from typing import Any

import numpy as np

# ---- topic and service names (relative to the robot namespace unless they start with /sim)
POSE = "loc/truth/pose"
TWIST = "loc/truth/twist"
EKF = "gnc/ekf"
COMMAND = "gnc/ctl/command"
SEGMENT = "gnc/ctl/segment"
TRAJ = "gnc/ctl/traj"
CANDIDATES = "gnc/ctl/candidates"
CTL_STOP = "gnc/ctl/stop"
FLIGHT_MODE = "mob/flight_mode"
MOB_STATE = "mob/state"
SET_FLIGHT_MODE = "mob/set_flight_mode"
FAULT = "sim/fault"
SIM_SCENARIO = "/sim/scenario"
BAG_STATE = "/sim/bag/state"
BAG_MESH = "/sim/bag/mesh"
CONTACTS = "/sim/contacts"
MARKERS = "/sim/markers"
SIM_RESET = "/sim/reset"
SIM_CONTROL = "/sim/control"
PLANNER_GLOBAL = "/mob/planner/global"
PLANNER_LOCAL = "/mob/planner/local"
PLANNER_FORMATION = "/mob/planner/formation"


def ns(robot: str) -> str:
    """Namespace prefix of a robot ('' for the default robot)."""
    return f"/{robot}" if robot else ""


def robot_topic(robot: str, name: str) -> str:
    """Absolute name of a per-robot topic: robot_topic('bumble', POSE) = /bumble/loc/truth/pose."""
    return f"{ns(robot)}/{name}"


class MotionState:
    """astrobee_msgs/MotionState.state values (as NASA ff_msgs; the .msg defines them too, and
    tests/control checks the two agree)."""

    INITIALIZING, IDLE, STOPPED, IDLING, STOPPING = 0, 1, 2, 3, 4
    PREPPING, BOOTSTRAPPING, PLANNING, PREPARING = 5, 6, 7, 8
    CONTROLLING, REPLANNING, HALTING = 9, 10, 11
    NAMES = {0: "INITIALIZING", 1: "IDLE", 2: "STOPPED", 3: "IDLING", 4: "STOPPING",
             5: "PREPPING", 6: "BOOTSTRAPPING", 7: "PLANNING", 8: "PREPARING",
             9: "CONTROLLING", 10: "REPLANNING", 11: "HALTING"}


class SimControl:
    """astrobee_msgs/SimControl request commands."""

    PAUSE, RESUME, STEP = 0, 1, 2


class Confidence:
    """astrobee_msgs/EkfState.confidence."""

    GOOD, POOR, LOST = 0, 1, 2


# ---- time
def to_ns(t: float) -> int:
    """Seconds -> integer nanoseconds (rounded once; negative clamps to 0)."""
    return max(0, int(round(float(t) * 1e9)))


def set_stamp_ns(stamp: Any, t_ns: int) -> None:
    sec, nsec = divmod(max(0, int(t_ns)), 1_000_000_000)
    stamp.sec, stamp.nanosec = int(sec), int(nsec)


def set_stamp(stamp: Any, t: float) -> None:
    """builtin_interfaces/Time from seconds (the one rule: see the module docstring)."""
    set_stamp_ns(stamp, to_ns(t))


def stamp_ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def stamp_s(stamp: Any) -> float:
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def stamp_key(stamp: Any) -> tuple[int, int]:
    return int(stamp.sec), int(stamp.nanosec)


# ---- vectors and poses
def vec(v: Any) -> np.ndarray:
    """geometry_msgs Vector3/Point -> (3,) float array."""
    return np.array([v.x, v.y, v.z], dtype=float)


def quat(q: Any) -> np.ndarray:
    """geometry_msgs/Quaternion -> [x, y, z, w]."""
    return np.array([q.x, q.y, q.z, q.w], dtype=float)


def set_vec(dst: Any, v: Any) -> None:
    dst.x, dst.y, dst.z = float(v[0]), float(v[1]), float(v[2])


def set_quat(dst: Any, q: Any) -> None:
    dst.x, dst.y, dst.z, dst.w = float(q[0]), float(q[1]), float(q[2]), float(q[3])


def set_pose(dst: Any, p: Any, q: Any) -> None:
    set_vec(dst.position, p)
    set_quat(dst.orientation, q)


def pose(msg: Any) -> tuple[np.ndarray, np.ndarray]:
    """geometry_msgs/Pose -> (position, [x, y, z, w])."""
    return vec(msg.position), quat(msg.orientation)
