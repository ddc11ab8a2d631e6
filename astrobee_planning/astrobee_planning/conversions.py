"""Conversions between planning objects and astrobee_msgs messages (attribute access only).

Message classes are passed in (e.g. roszen.message_class(...)), so this module imports no
transport. ControlState.when holds the time from the trajectory start plus `t_offset`;
twist.angular and accel.angular are world-frame angular velocity/acceleration.
"""
from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np

from .quaternion_poly import QuaternionPolynomial
from .trajectory import BezierPiece, State, Trajectory


def _set_vec(v: Any, a: np.ndarray) -> None:
    v.x, v.y, v.z = float(a[0]), float(a[1]), float(a[2])


def _vec(v: Any) -> np.ndarray:
    return np.array([float(v.x), float(v.y), float(v.z)])


def set_time(stamp: Any, t: float) -> None:
    sec = int(np.floor(t))
    stamp.sec = sec
    stamp.nanosec = min(int(round((t - sec) * 1e9)), 999_999_999)


def time_of(stamp: Any) -> float:
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def pose_to_arrays(pose: Any) -> tuple[np.ndarray, np.ndarray]:
    """geometry_msgs/Pose -> (position (3,), quaternion [x,y,z,w])."""
    o = pose.orientation
    return _vec(pose.position), np.array([float(o.x), float(o.y), float(o.z), float(o.w)])


def set_pose(pose: Any, p: np.ndarray, q: np.ndarray) -> None:
    _set_vec(pose.position, p)
    o = pose.orientation
    o.x, o.y, o.z, o.w = (float(x) for x in q)


def states_to_msgs(states: State, control_state_cls: Callable[[], Any], t_offset: float = 0.0
                   ) -> list[Any]:
    """Sampled states -> list of ControlState messages."""
    out = []
    for i in range(len(states)):
        m = control_state_cls()
        set_time(m.when, t_offset + float(states.t[i]))
        set_pose(m.pose, states.pos[i], states.quat[i])
        _set_vec(m.twist.linear, states.vel[i])
        _set_vec(m.twist.angular, states.omega[i])
        _set_vec(m.accel.linear, states.acc[i])
        _set_vec(m.accel.angular, states.alpha[i])
        out.append(m)
    return out


def msgs_to_states(msgs: Sequence[Any]) -> State:
    """ControlState messages -> State arrays (t from `when`)."""
    t = np.array([time_of(m.when) for m in msgs])
    pos = np.array([_vec(m.pose.position) for m in msgs]).reshape(-1, 3)
    quat = np.array([pose_to_arrays(m.pose)[1] for m in msgs]).reshape(-1, 4)
    g = lambda f: np.array([_vec(f(m)) for m in msgs]).reshape(-1, 3)  # noqa: E731
    return State(t, pos, g(lambda m: m.twist.linear), g(lambda m: m.accel.linear), quat,
                 g(lambda m: m.twist.angular), g(lambda m: m.accel.angular))


def control_state_to_dict(m: Any) -> dict[str, np.ndarray]:
    """One ControlState -> dict(pos, vel, acc, quat, omega, alpha) for the local planner."""
    p, q = pose_to_arrays(m.pose)
    return {"pos": p, "quat": q, "vel": _vec(m.twist.linear), "omega": _vec(m.twist.angular),
            "acc": _vec(m.accel.linear), "alpha": _vec(m.accel.angular)}


def bezier_to_msg(piece: BezierPiece, bezier_cls: Callable[[], Any], point_cls: Callable[[], Any]) -> Any:
    m = bezier_cls()
    m.t0 = float(piece.t0)
    m.duration = float(piece.duration)
    pts = []
    for p in piece.points:
        pt = point_cls()
        _set_vec(pt, p)
        pts.append(pt)
    m.control_points = pts
    return m


def msg_to_bezier(m: Any) -> BezierPiece:
    return BezierPiece(np.array([_vec(p) for p in m.control_points]).reshape(-1, 3),
                       float(m.t0), float(m.duration))


def quatpoly_to_msg(p: QuaternionPolynomial, cls: Callable[[], Any]) -> Any:
    m = cls()
    m.t0 = float(p.t0)
    m.duration = float(p.duration)
    m.coefficients = np.asarray(p.coefficients, dtype=float).reshape(24)
    return m


def msg_to_quatpoly(m: Any) -> QuaternionPolynomial:
    return QuaternionPolynomial(np.asarray(m.coefficients, dtype=float).reshape(6, 4),
                                float(m.t0), float(m.duration))


def trajectory_from_msgs(position: Sequence[Any], attitude: Sequence[Any]) -> Trajectory:
    """Exact trajectory from BezierCurve[] and QuaternionPolynomial[] messages."""
    if not position or not attitude:
        raise ValueError("a trajectory needs at least one position and one attitude piece")
    return Trajectory([msg_to_bezier(m) for m in position], [msg_to_quatpoly(m) for m in attitude])
