"""Attitude plans along a position spline: face-forward heading and start-to-goal blends.

Face-forward: the body x axis follows the direction of travel. The first heading is yaw/pitch
of the initial direction (no roll, body z up); afterwards the heading is carried by parallel
transport (the minimal rotation taking one tangent to the next), which is smooth and has no
gimbal singularity when the path goes vertical (Node 3 -> Cupola). One quintic quaternion
polynomial per position segment, matching the transported heading, its angular velocity
w = u x du/dt and a finite-difference angular acceleration at the joints (zero at the ends).
"""
from __future__ import annotations

import numpy as np

from astrobee import rotations as rot

from .position_planner import Spline
from .quaternion_poly import QuaternionPolynomial


def heading_from_direction(u: np.ndarray) -> np.ndarray:
    """Quaternion with body x along unit vector u, no roll (yaw then pitch)."""
    yaw = np.arctan2(u[1], u[0])
    pitch = -np.arcsin(np.clip(u[2], -1.0, 1.0))
    return rot.from_euler(0.0, pitch, yaw)


def min_rotation(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Smallest rotation taking unit vector u onto unit vector v."""
    c = float(np.dot(u, v))
    axis = np.cross(u, v)
    s = np.linalg.norm(axis)
    if s < 1e-12:
        if c > 0:
            return rot.IDENTITY.copy()
        perp = np.cross(u, [1.0, 0, 0]) if abs(u[0]) < 0.9 else np.cross(u, [0, 1.0, 0])
        return rot.from_axis_angle(perp, np.pi)
    return rot.from_axis_angle(axis / s, np.arctan2(s, c))


def min_rotations(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """`min_rotation` of each row pair of unit vectors u, v (K, 3) -> (K, 4), vectorised."""
    u, v = np.atleast_2d(u), np.atleast_2d(v)
    c = np.sum(u * v, axis=1)
    axis = np.cross(u, v)
    s = np.linalg.norm(axis, axis=1)
    half = 0.5 * np.arctan2(s, c)
    out = np.zeros((len(u), 4))
    ok = s >= 1e-12
    out[ok, :3] = axis[ok] / s[ok, None] * np.sin(half[ok])[:, None]
    out[ok, 3] = np.cos(half[ok])
    out[~ok & (c > 0), 3] = 1.0
    for k in np.flatnonzero(~ok & (c <= 0)):       # opposite directions: half a turn
        out[k] = min_rotation(u[k], v[k])
    return out


def transported_headings(q0: np.ndarray, u: np.ndarray) -> np.ndarray:
    """q[0] = q0, q[k] = min_rotation(u[k-1], u[k]) (x) q[k-1]: the parallel transport along the
    unit tangents u (K, 3), by a prefix scan of quaternion products (log2 K vectorised steps)."""
    r = min_rotations(u[:-1], u[1:])                 # (K-1, 4)
    pre = r.copy()                                   # pre[k] = r[k] (x) ... (x) r[0] once scanned
    d = 1
    while d < len(pre):
        pre[d:] = rot.multiply(pre[d:], pre[:-d])
        d *= 2
    q = np.empty((len(u), 4))
    q[0] = q0
    q[1:] = rot.multiply(pre, np.broadcast_to(q0, pre.shape))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _tangents(spline: Spline, t: np.ndarray) -> np.ndarray:
    """Unit direction of travel at times t; where the speed vanishes, the nearest defined one."""
    v = spline.evaluate(t, 1)
    sp = np.linalg.norm(v, axis=1)
    ok = sp > 1e-6 * max(1e-9, sp.max())
    if not ok.any():
        return np.tile([1.0, 0.0, 0.0], (len(t), 1))
    idx = np.arange(len(t))
    good = idx[ok]
    nearest = good[np.clip(np.searchsorted(good, idx), 0, len(good) - 1)]
    v = v[nearest]
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def face_forward(spline: Spline, t_offset: float = 0.0, samples_per_second: float = 4.0
                 ) -> tuple[list[QuaternionPolynomial], np.ndarray, np.ndarray]:
    """Attitude pieces over the spline (times shifted by t_offset), plus the heading at its
    start and end."""
    T = spline.duration
    ts = np.linspace(0.0, T, max(50, int(T * samples_per_second)))
    joints = np.concatenate([[0.0], np.cumsum(spline.durations)])
    ts = np.unique(np.concatenate([ts, joints]))
    u = _tangents(spline, ts)
    q = transported_headings(heading_from_direction(u[0]), u)
    # angular velocity of the transported frame: w = u x du/dt (analytic from v, a)
    v = spline.evaluate(ts, 1)
    a = spline.evaluate(ts, 2)
    sp = np.linalg.norm(v, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        udot = (a - u * np.sum(u * a, axis=1, keepdims=True)) / sp
    udot = np.where(sp > 1e-4, udot, 0.0)
    w = np.cross(u, udot)
    alpha = np.gradient(w, ts, axis=0)
    ji = np.searchsorted(ts, joints)
    w[ji[0]] = w[ji[-1]] = 0.0
    alpha[ji[0]] = alpha[ji[-1]] = 0.0
    pieces = []
    for s in range(len(spline.durations)):
        i0, i1 = ji[s], ji[s + 1]
        pieces.append(QuaternionPolynomial.from_boundary(
            q[i0], w[i0], alpha[i0], q[i1], w[i1], alpha[i1], spline.durations[s],
            t0=t_offset + joints[s]))
    return pieces, q[0], q[-1]


def blend(q0: np.ndarray, q1: np.ndarray, duration: float, t0: float = 0.0) -> QuaternionPolynomial:
    """Rest-to-rest rotation from q0 to q1 over `duration` (the position moves meanwhile)."""
    z = np.zeros(3)
    return QuaternionPolynomial.from_boundary(q0, z, z, q1, z, z, duration, t0)
