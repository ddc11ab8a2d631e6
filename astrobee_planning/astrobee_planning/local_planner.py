"""Local planner: one quintic Bezier + one quintic quaternion polynomial between two full states.

Position: with position, velocity and acceleration given at both ends, the minimum-integrated-
squared-jerk curve is the quintic, i.e. a degree-5 Bezier whose six control points are fixed by
the boundary values (closed form, no solve; a degree-7 curve with free interior points would
reduce to the same quintic): astrobee.bezier.control_points.
Attitude: the quintic quaternion polynomial of quaternion_poly (world-frame rates).
`plan_batch` does N plans at once (vectorised) for the sampling MPC.
Requests from outside go through `plan_within_limits` (bounded duration, start, goal and path
in the station, every rate within the flight mode's hard limits; ValueError otherwise).
"""
from __future__ import annotations

import numpy as np

from astrobee import bezier, config, flight_modes
from astrobee import rotations as rot

from .errors import OutsideSafeSet
from .quaternion_poly import _H, QuaternionPolynomial
from .trajectory import BezierPiece, Trajectory

_HT = np.ascontiguousarray(_H)
MAX_DURATION = 600.0      # s: longest local plan (a 1e5 s request returned a million states)
KEEP_IN_TOLERANCE = 0.05  # m: how far outside the keep-in boxes a local plan's centre may be
                          # (state estimates at a wall); the robot's sphere is not checked here
LIMIT_TOLERANCE = 1e-6    # relative slack on the flight mode's limits (rounding)
CHECK_SAMPLES = 200       # samples of a local plan checked against the limits and keep-in


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return rot.multiply(a, b)


def quaternion_coefficients(q0, w0, al0, q1, w1, al1, duration) -> np.ndarray:
    """Quintic quaternion polynomial coefficients (..., 6, 4) (world-frame rates); q1 is taken on
    q0's hemisphere."""
    q0 = np.asarray(q0, dtype=float)
    q1 = np.asarray(q1, dtype=float)
    q0 = q0 / np.linalg.norm(q0, axis=-1, keepdims=True)
    q1 = q1 / np.linalg.norm(q1, axis=-1, keepdims=True)
    q1 = np.where(np.sum(q0 * q1, axis=-1, keepdims=True) < 0, -q1, q1)
    T = np.asarray(duration, dtype=float)[..., None]
    w0, al0, w1, al1 = (np.asarray(x, dtype=float) for x in (w0, al0, w1, al1))
    z = np.zeros(w0.shape[:-1] + (1,))
    pw0 = np.concatenate([w0, z], -1)
    pw1 = np.concatenate([w1, np.zeros(w1.shape[:-1] + (1,))], -1)
    pa0 = np.concatenate([al0, np.zeros(al0.shape[:-1] + (1,))], -1)
    pa1 = np.concatenate([al1, np.zeros(al1.shape[:-1] + (1,))], -1)
    d0 = 0.5 * _qmul(pw0, q0)
    d1 = 0.5 * _qmul(pw1, q1)
    dd0 = 0.5 * _qmul(pa0, q0) - 0.25 * np.sum(w0 * w0, -1, keepdims=True) * q0
    dd1 = 0.5 * _qmul(pa1, q1) - 0.25 * np.sum(w1 * w1, -1, keepdims=True) * q1
    f = np.stack(np.broadcast_arrays(q0, T * d0, T * T * dd0, q1, T * d1, T * T * dd1), axis=-2)
    return np.einsum("ij,...jk->...ik", _HT, f)


def _pure_times(v, q):
    """[v, 0] (x) q for a 3-vector v and quaternion q (Python floats)."""
    vx, vy, vz = v
    qx, qy, qz, qw = q
    return (qw * vx + vy * qz - vz * qy, qw * vy + vz * qx - vx * qz,
            qw * vz + vx * qy - vy * qx, -(vx * qx + vy * qy + vz * qz))


def plan_single(p0, v0, a0, q0, w0, al0, p1, v1, a1, q1, w1, al1, duration: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """One plan with Python-float arithmetic (the fast path of `plan`): (points (6,3), coeffs (6,4))."""
    T = float(duration)
    k1, k2 = T / 5.0, T * T / 20.0
    p0, v0, a0, p1, v1, a1 = (tuple(map(float, x)) for x in (p0, v0, a0, p1, v1, a1))
    pts = np.array([p0,
                    [p0[i] + v0[i] * k1 for i in range(3)],
                    [p0[i] + 2 * v0[i] * k1 + a0[i] * k2 for i in range(3)],
                    [p1[i] - 2 * v1[i] * k1 + a1[i] * k2 for i in range(3)],
                    [p1[i] - v1[i] * k1 for i in range(3)],
                    p1])
    q0 = tuple(map(float, q0))
    q1 = tuple(map(float, q1))
    n0 = sum(x * x for x in q0) ** 0.5
    n1 = sum(x * x for x in q1) ** 0.5
    sgn = 1.0 if sum(a * b for a, b in zip(q0, q1)) >= 0 else -1.0
    q0 = tuple(x / n0 for x in q0)
    q1 = tuple(sgn * x / n1 for x in q1)
    rows = []
    for q, w, al in ((q0, w0, al0), (q1, w1, al1)):
        w = tuple(map(float, w))
        d = _pure_times(w, q)
        e = _pure_times(tuple(map(float, al)), q)
        ww = 0.25 * (w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
        rows += [q, tuple(0.5 * T * x for x in d),
                 tuple(T * T * (0.5 * e[i] - ww * q[i]) for i in range(4))]
    return pts, _HT @ np.array(rows)


def plan(start, goal, duration: float, t0: float = 0.0) -> Trajectory:
    """One-piece trajectory between two full states (dicts or State-like objects with pos, vel,
    acc, quat, omega, alpha; world-frame rates) over `duration` seconds."""
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError("duration must be positive and finite")
    if duration > MAX_DURATION:
        raise ValueError(f"duration {duration:.6g} s is longer than the {MAX_DURATION:g} s a local plan may last")
    g = lambda s, k: np.asarray(s[k] if isinstance(s, dict) else getattr(s, k), dtype=float)  # noqa: E731
    vals = [g(start, k) for k in ("pos", "vel", "acc", "quat", "omega", "alpha")] + \
           [g(goal, k) for k in ("pos", "vel", "acc", "quat", "omega", "alpha")]
    if not np.all(np.isfinite(np.concatenate(vals))):
        raise ValueError("states must be finite")
    for q in (vals[3], vals[9]):
        if abs(np.linalg.norm(q) - 1.0) > 1e-3:
            raise ValueError("quaternions must have unit norm")
    p0, v0, a0, q0, w0, al0, p1, v1, a1, q1, w1, al1 = vals
    pts, coef = plan_single(p0, v0, a0, q0, w0, al0, p1, v1, a1, q1, w1, al1, duration)
    return Trajectory([BezierPiece(pts, float(t0), float(duration))],
                      [QuaternionPolynomial(coef, float(t0), float(duration))])


def _outside_keep_in(pos: np.ndarray, keep_in: np.ndarray, tol: float) -> np.ndarray:
    """Per row of pos (M, 3): outside every keep-in box grown by tol."""
    inside = np.all((pos[:, None, :] >= keep_in[None, :, :3] - tol)
                    & (pos[:, None, :] <= keep_in[None, :, 3:] + tol), axis=2)
    return ~inside.any(axis=1)


def _limit_excess(tr: Trajectory, mode) -> tuple[str, float, float] | None:
    """(quantity, peak, limit) of the worst rate beyond the mode's hard limits, or None."""
    st = tr.sample(np.linspace(0.0, tr.duration, CHECK_SAMPLES))
    worst = None
    for key, lim, unit in (("vel", mode.hard_limit_vel, "m/s"), ("acc", mode.hard_limit_accel, "m/s^2"),
                           ("omega", mode.hard_limit_omega, "rad/s"), ("alpha", mode.hard_limit_alpha, "rad/s^2")):
        peak = float(np.max(np.linalg.norm(getattr(st, key), axis=1)))
        if peak > lim * (1 + LIMIT_TOLERANCE) and (worst is None or peak / lim > worst[1] / worst[2]):
            worst = (f"|{key}| {peak:.4g} {unit}", peak, lim)
    return worst


def shortest_duration(start, goal, mode, longest: float = MAX_DURATION) -> float | None:
    """About the shortest duration (within 1%) whose local plan stays within the mode's limits
    (doubling then bisection), or None when not even `longest` does."""
    if _limit_excess(plan(start, goal, longest), mode) is not None:
        return None
    lo, hi = 0.0, 1.0
    while hi < longest and _limit_excess(plan(start, goal, hi), mode) is not None:
        lo, hi = hi, min(2.0 * hi, longest)
    while hi - lo > 0.01 * hi:
        mid = 0.5 * (lo + hi)
        if _limit_excess(plan(start, goal, mid), mode) is None:
            hi = mid
        else:
            lo = mid
    return hi


def plan_within_limits(start, goal, duration: float, flight_mode: str | None = None,
                       t0: float = 0.0, keep_in: np.ndarray | None = None) -> Trajectory:
    """`plan` for a request from outside, with bounds: duration in (0, MAX_DURATION]; the
    start, the goal and every sampled centre on the way inside the keep-in boxes (config/iss.yaml
    unless given; KEEP_IN_TOLERANCE slack; OutsideSafeSet otherwise); the plan's |v|, |a|, |w|,
    |alpha| within the flight mode's hard limits. A duration too short for the limits is
    rejected, not stretched (the caller asked for that timing), with the shortest that would do.
    Raises ValueError (one line)."""
    tr = plan(start, goal, duration, t0)
    keep_in = config.keep_in_boxes() if keep_in is None else np.asarray(keep_in, dtype=float)
    g = lambda s: np.asarray(s["pos"] if isinstance(s, dict) else s.pos, dtype=float)  # noqa: E731
    for name, p in (("start", g(start)), ("goal", g(goal))):
        if _outside_keep_in(p[None], keep_in, KEEP_IN_TOLERANCE)[0]:
            raise OutsideSafeSet(f"local plan {name} {np.round(p, 3).tolist()} is outside the "
                                 f"station's keep-in boxes")
    pos = tr.sample(np.linspace(0.0, duration, CHECK_SAMPLES) + t0).pos
    out = _outside_keep_in(pos, keep_in, KEEP_IN_TOLERANCE)
    if out.any():
        raise OutsideSafeSet(f"local plan leaves the station's keep-in boxes at "
                             f"{np.round(pos[np.argmax(out)], 3).tolist()}")
    try:
        mode = flight_modes.get(flight_mode or None)
    except flight_modes.UnknownFlightMode as exc:
        raise ValueError(str(exc)) from exc
    if not mode.control_enabled or mode.hard_limit_vel <= 0:
        raise ValueError(f"flight mode {mode.name!r} does not allow motion")
    worst = _limit_excess(tr, mode)
    if worst is not None:
        need = shortest_duration(start, goal, mode)
        hint = (f"; at least {need:.3g} s would do" if need is not None else
                "; no duration up to the maximum would (boundary states beyond the limits?)")
        raise ValueError(f"a {duration:.6g} s local plan needs {worst[0]}, beyond the "
                         f"{mode.name} limit {worst[2]:.4g}{hint}")
    return tr


def plan_batch(p0, v0, a0, q0, w0, al0, p1, v1, a1, q1, w1, al1, durations
               ) -> tuple[np.ndarray, np.ndarray]:
    """N plans at once: (control points (N, 6, 3), quaternion coefficients (N, 6, 4))."""
    return (bezier.control_points(p0, v0, a0, p1, v1, a1, durations),
            quaternion_coefficients(q0, w0, al0, q1, w1, al1, durations))


def evaluate_batch(points: np.ndarray, coefficients: np.ndarray, durations: np.ndarray,
                   s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities, accelerations (N, M, 3) and unit quaternions (N, M, 4) of N local
    plans at M normalised times s in [0, 1]."""
    s = np.asarray(s, dtype=float)
    B = bezier.bernstein(5, s)                          # (M, 6)
    B1 = bezier.bernstein(4, s) @ bezier.difference_matrix(5, 1)
    B2 = bezier.bernstein(3, s) @ bezier.difference_matrix(5, 2)
    T = np.asarray(durations, dtype=float)[:, None, None]
    pos = np.einsum("mi,nik->nmk", B, points)
    vel = np.einsum("mi,nik->nmk", B1, points) / T
    acc = np.einsum("mi,nik->nmk", B2, points) / T**2
    q = np.einsum("mj,njk->nmk", s[:, None] ** np.arange(6), coefficients)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return pos, vel, acc, q
