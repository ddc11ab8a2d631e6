"""Position planner: near time-optimal, minimum-jerk piecewise Bezier spline through safe boxes.

Geometry and timing are separated. For fixed segment durations T the spline is the solution of
one convex QP (spline_qp.py: minimum jerk, control points in their boxes, C3 joints). No
velocity or acceleration row is in the QP: box containment does not depend on time, so any
solution can be slowed down uniformly until it meets the flight mode's limits, and that scale
is computed from a tight bound on the NORMS of velocity and acceleration (the convex hull of the
subdivided derivative curves), not a per-axis budget.

Timing: T starts from a trapezoidal speed profile along the reference polyline (with corner
speeds from the turning angles), and a handful of retiming steps stretch or shrink each
segment by its own limit usage; the best uniformly-scaled result is kept: 4-8 solves per
route instead of a duration bisection (73-127). Segments follow the profile: short where the
speed changes (so the piecewise curve can hold the acceleration at its limit), up to MAX_LEG in
cruise; the joints on straight legs are pulled towards the profile's points (a quadratic
tracking term), those near a corner are left free so the curve cuts it.
The time-optimality gap is reported against the trapezoidal lower bound on the shortest
polyline through the route's boxes.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import lru_cache
from math import comb

import numpy as np

from astrobee import bezier

from .boxes import SafeSet, safe_set
from .errors import PlanningError
from .spline_qp import CONTINUITY, DEGREE, SplineQP

MAX_LEG = 2.0           # m: cruise legs are split into segments at most this long
CORNER_REACH = 1.0      # share of the shorter leg near a corner left free (the curve cuts it)
DV_FRACTION = 0.34      # a segment changes speed by at most this share of v_max
MIN_SEGMENT_TIME = 0.2  # x v/a: shortest segment the profile makes inside a leg
MAX_SEGMENTS = 40       # split no further than this many segments in all (QP size)
RETIME_STEPS = 7        # retiming solves after the first (stops early without progress)
TRACK_WEIGHT = 1.0      # pull of the straight-leg joints to the speed profile's points
HULL_SPLITS = 2         # derivative curves subdivided 2^k times for the norm bound


@dataclass
class Spline:
    """Piecewise Bezier position spline: segment i spans [t0[i], t0[i] + durations[i]]."""
    points: np.ndarray          # (S, n+1, 3)
    durations: np.ndarray       # (S,)
    boxes: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))  # (S, 6) box per segment

    @property
    def t0(self) -> np.ndarray:
        return np.concatenate([[0.0], np.cumsum(self.durations)[:-1]])

    @property
    def duration(self) -> float:
        return float(np.sum(self.durations))

    def locate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Segment index and local parameter s in [0, 1] of times t (clipped to the spline)."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        ends = np.cumsum(self.durations)
        idx = np.minimum(np.searchsorted(ends, t, side="right"), len(self.durations) - 1)
        s = (t - self.t0[idx]) / self.durations[idx]
        return idx, np.clip(s, 0.0, 1.0)

    def evaluate(self, t: np.ndarray, k: int = 0) -> np.ndarray:
        """k-th time derivative at times t, shape (len(t), 3) (vectorised over segments)."""
        idx, s = self.locate(t)
        n = self.points.shape[1] - 1
        if k > n:
            return np.zeros((len(s), 3))
        d = bezier.difference_matrix(n, k)                                  # (n+1-k, n+1)
        coef = bezier.bernstein_power_matrix(n - k).T @ d                   # monomial rows
        c = np.einsum("ij,sjk->sik", coef, self.points) / self.durations[:, None, None] ** k
        return bezier.horner(c[idx], s)

    def scaled(self, factor: float) -> "Spline":
        """The same path slowed down by `factor` (durations times factor)."""
        return Spline(self.points.copy(), self.durations * factor, self.boxes.copy())


@lru_cache(maxsize=None)
def _subdivision(m: int, splits: int) -> np.ndarray:
    """(2^splits (m+1), m+1): control points of the 2^splits equal pieces of a degree-m curve."""
    left = np.zeros((m + 1, m + 1))
    right = np.zeros((m + 1, m + 1))
    for i in range(m + 1):
        for j in range(i + 1):
            left[i, j] = comb(i, j) / 2.0 ** i
        for j in range(i, m + 1):
            right[i, j] = comb(m - i, j - i) / 2.0 ** (m - i)
    mats = [np.eye(m + 1)]
    for _ in range(splits):
        mats = [x for mm in mats for x in (left @ mm, right @ mm)]
    out = np.vstack(mats)
    out.setflags(write=False)
    return out


def peak_bounds(points: np.ndarray, T: np.ndarray, splits: int = HULL_SPLITS
                ) -> tuple[np.ndarray, np.ndarray]:
    """Per segment, upper bounds of max |v| and max |a| (norms): the largest control point of
    the subdivided derivative curves (convex hull); within ~1% of the true peaks."""
    n = points.shape[1] - 1
    T = np.asarray(T, float)[:, None, None]
    v = n * np.diff(points, axis=1) / T
    a = n * (n - 1) * np.diff(points, 2, axis=1) / T ** 2
    vs = np.einsum("ij,sjk->sik", _subdivision(n - 1, splits), v)
    as_ = np.einsum("ij,sjk->sik", _subdivision(n - 2, splits), a)
    return np.linalg.norm(vs, axis=2).max(axis=1), np.linalg.norm(as_, axis=2).max(axis=1)


def reference_polyline(route_boxes: np.ndarray, start: np.ndarray, goal: np.ndarray,
                       iterations: int = 60) -> np.ndarray:
    """[start, w_1, ..., w_{S-1}, goal] with w_i in the overlap of boxes i-1 and i: the shortest
    such polyline, by projected Gauss-Seidel on reweighted squared legs (weights 1/length)."""
    S = len(route_boxes)
    ov = np.array([np.concatenate([np.maximum(route_boxes[i, :3], route_boxes[i + 1, :3]),
                                   np.minimum(route_boxes[i, 3:], route_boxes[i + 1, 3:])])
                   for i in range(S - 1)]).reshape(-1, 6)
    pts = np.array([start] + [0.5 * (o[:3] + o[3:]) for o in ov] + [goal], dtype=float)
    for it in range(iterations):
        w = 1.0 / np.maximum(np.linalg.norm(np.diff(pts, axis=0), axis=1), 1e-3) if it >= 10 \
            else np.ones(S)
        for i in range(1, S):
            o = ov[i - 1]
            m = (w[i - 1] * pts[i - 1] + w[i] * pts[i + 1]) / (w[i - 1] + w[i])
            pts[i] = np.clip(m, o[:3], o[3:])
    return pts


def profile_segments(poly: np.ndarray, vertex_speed: np.ndarray, v: float, a: float,
                     dv: float, max_leg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Break every polyline leg where a trapezoidal speed profile (rest at the ends, at most
    `vertex_speed` at inner vertices, acceleration a) has changed speed by dv, and cruises at
    most max_leg: short segments where the speed changes (so piecewise min-jerk curves can
    follow a flat acceleration), long ones in cruise. Returns (points (S+1, 3), leg index of
    each segment (S,), durations (S,) of the profile, tracked joints (S+1, 3): the points
    with NaN where the curve should cut a corner: within the corner arc's reach of a vertex)."""
    legs = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    reach = np.zeros(len(poly))
    if len(legs) > 1:
        reach[1:-1] = np.where(vertex_speed < v, CORNER_REACH * np.minimum(legs[:-1], legs[1:]), 0.0)
    S = len(legs)
    vv = np.full(S + 1, v)
    vv[0] = vv[-1] = 0.0
    vv[1:-1] = np.minimum(vv[1:-1], vertex_speed)
    for i in range(1, S + 1):
        vv[i] = min(vv[i], np.sqrt(vv[i - 1] ** 2 + 2 * a * legs[i - 1]))
    for i in range(S - 1, -1, -1):
        vv[i] = min(vv[i], np.sqrt(vv[i + 1] ** 2 + 2 * a * legs[i]))
    pts, leg_of, durs, track = [poly[0]], [], [], [poly[0]]
    for i in range(S):
        L, va, vb = legs[i], vv[i], vv[i + 1]
        vp = max(min(v, np.sqrt(max((2 * a * L + va * va + vb * vb) / 2, 0.0))), va, vb, 1e-9)
        la, ld = (vp * vp - va * va) / (2 * a), (vp * vp - vb * vb) / (2 * a)
        lc = max(L - la - ld, 0.0)
        marks = [(0.0, 0.0)]                      # (distance along the leg, time)
        na = int(np.ceil((vp - va) / dv - 1e-9))
        for j in range(1, na + 1):
            vj = va + j * (vp - va) / na
            marks.append(((vj * vj - va * va) / (2 * a), (vj - va) / a))
        t_a = (vp - va) / a
        nc = int(np.ceil(lc / max_leg - 1e-9)) if lc > 1e-3 else 0
        for j in range(1, nc + 1):
            marks.append((la + lc * j / nc, t_a + lc * j / nc / vp))
        t_c = t_a + lc / vp
        nd = int(np.ceil((vp - vb) / dv - 1e-9))
        for j in range(1, nd + 1):
            vj = vp - j * (vp - vb) / nd
            marks.append((la + lc + (vp * vp - vj * vj) / (2 * a), t_c + (vp - vj) / a))
        # drop marks closer in time than min_dt to the previous one (short segments make the
        # QP's jerk weights, 1/T^5, badly conditioned); the leg's end is always kept
        min_dt = MIN_SEGMENT_TIME * v / a
        keep = [marks[0]]
        for m in marks[1:-1]:
            if m[1] - keep[-1][1] >= min_dt:
                keep.append(m)
        if len(keep) > 1 and marks[-1][1] - keep[-1][1] < min_dt:
            keep[-1] = marks[-1]
        else:
            keep.append(marks[-1])
        keep[-1] = (L, keep[-1][1])
        u = (poly[i + 1] - poly[i]) / max(L, 1e-12)
        for (d0, t0), (d1, t1) in zip(keep[:-1], keep[1:]):
            pts.append(poly[i] + u * d1)
            free = d1 > L - reach[i + 1] - 1e-9 or d1 < reach[i] + 1e-9
            track.append(np.full(3, np.nan) if free else pts[-1])
            leg_of.append(i)
            durs.append(max(t1 - t0, 1e-2))
    return np.array(pts), np.array(leg_of), np.array(durs), np.array(track)


def trapezoid_time(length: float, v: float, a: float) -> float:
    """Rest-to-rest time over `length` with speed v and acceleration a (the lower bound)."""
    if length <= 0:
        return 0.0
    if length <= v * v / a:
        return 2.0 * np.sqrt(length / a)
    return length / v + v / a


def _leg_time(L: float, va: float, vb: float, v: float, a: float) -> float:
    vp = min(v, np.sqrt(max((2 * a * L + va * va + vb * vb) / 2, 0.0)))
    vp = max(vp, va, vb, 1e-9)
    d = (2 * vp * vp - va * va - vb * vb) / (2 * a)
    return (vp - va) / a + (vp - vb) / a + max(L - d, 0.0) / vp


def initial_durations(poly: np.ndarray, v: float, a: float, vertex_speed: np.ndarray | None = None
                      ) -> np.ndarray:
    """Segment durations from a speed profile along the polyline: rest at the ends, at most
    `vertex_speed` at the inner vertices (corners), accelerations of a (forward/backward pass)."""
    legs = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    S = len(legs)
    vv = np.full(S + 1, v)
    vv[0] = vv[-1] = 0.0
    if vertex_speed is not None:
        vv[1:-1] = np.minimum(vv[1:-1], vertex_speed)
    for i in range(1, S + 1):
        vv[i] = min(vv[i], np.sqrt(vv[i - 1] ** 2 + 2 * a * legs[i - 1]))
    for i in range(S - 1, -1, -1):
        vv[i] = min(vv[i], np.sqrt(vv[i + 1] ** 2 + 2 * a * legs[i]))
    T = np.array([_leg_time(legs[i], vv[i], vv[i + 1], v, a) for i in range(S)])
    return np.maximum(T, 0.05 * max(T.sum(), 1.0) / S)


def corner_speeds(poly: np.ndarray, v: float, a: float) -> np.ndarray:
    """Speed at each inner vertex: an arc tangent to both legs within half of the shorter leg
    has radius r = d / tan(theta/2); v^2 / r <= a."""
    legs = np.diff(poly, axis=0)
    ln = np.linalg.norm(legs, axis=1)
    u = legs / np.maximum(ln[:, None], 1e-12)
    cos = np.clip(np.sum(u[:-1] * u[1:], axis=1), -1.0, 1.0)
    half = 0.5 * np.arccos(cos)
    d = 0.5 * np.minimum(ln[:-1], ln[1:])
    with np.errstate(divide="ignore"):
        r = np.where(half > 1e-6, d / np.tan(half), np.inf)
    return np.minimum(v, np.sqrt(a * r))


@dataclass
class PositionPlan:
    spline: Spline
    route: list[int]
    solves: int
    planning_time: float
    lower_bound: float = 0.0            # s: trapezoid on the shortest polyline of the route
    iterations: int = 0                 # interior-point iterations over all QP solves

    @property
    def gap(self) -> float:
        """Relative time-optimality gap against the trapezoidal lower bound."""
        return self.spline.duration / self.lower_bound - 1.0 if self.lower_bound > 0 else 0.0


def _usage(x: np.ndarray, T: np.ndarray, v_max: float, a_max: float) -> np.ndarray:
    vb, ab = peak_bounds(x, T)
    return np.maximum(vb / v_max, np.sqrt(ab / a_max))


def plan_position(start: np.ndarray, goal: np.ndarray, v_max: float, a_max: float,
                  safe: SafeSet | None = None, v0: np.ndarray | None = None,
                  v1: np.ndarray | None = None, a0: np.ndarray | None = None,
                  a1: np.ndarray | None = None, refine_rounds: int = RETIME_STEPS,
                  degree: int = DEGREE, max_leg: float = MAX_LEG) -> PositionPlan:
    """Near time-optimal (for the norm limits) minimum-jerk spline from start to goal inside
    `safe`. Boundary velocity/acceleration default to rest. Raises OutsideSafeSet, NoRoute,
    PlanningError."""
    t_start = time.perf_counter()
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    z = np.zeros(3)
    v0, v1, a0, a1 = (z if v is None else np.asarray(v, float) for v in (v0, v1, a0, a1))
    for name, v in (("start", start), ("goal", goal), ("v0", v0), ("v1", v1), ("a0", a0), ("a1", a1)):
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ValueError(f"{name} must be a finite 3-vector")
    if not (v_max > 0 and a_max > 0):
        raise PlanningError("the flight mode's velocity/acceleration limits are zero")
    if max(np.linalg.norm(v0), np.linalg.norm(v1)) > v_max or max(np.linalg.norm(a0), np.linalg.norm(a1)) > a_max:
        raise PlanningError("boundary velocity or acceleration beyond the limits")
    safe = safe_set() if safe is None else safe
    route = safe.route(start, goal)
    rboxes = safe.boxes[route]
    poly = reference_polyline(rboxes, start, goal)
    length = float(np.linalg.norm(np.diff(poly, axis=0), axis=1).sum())
    lower = trapezoid_time(length, v_max, a_max)
    corners = corner_speeds(poly, v_max, a_max)
    dv = v_max * DV_FRACTION
    while True:
        _, leg_of, T, track = profile_segments(poly, corners, v_max, a_max, dv, max_leg)
        if len(T) <= MAX_SEGMENTS or dv >= v_max:
            break
        dv *= 1.3
        max_leg *= 1.3
    route = [route[i] for i in leg_of]
    rboxes = rboxes[leg_of]
    bc = np.stack([start, v0, a0, goal, v1, a1], axis=1)       # (3, 6)
    qp = SplineQP(rboxes[:, :3], rboxes[:, 3:], degree, CONTINUITY, track, TRACK_WEIGHT)
    best = None
    stale = 0
    for step in range(refine_rounds + 1):
        x = qp.solve(T, bc)
        if x is None:
            if best is not None:
                break
            T = T * 1.5
            continue
        u = _usage(x, T, v_max, a_max)
        total = float(u.max()) * T.sum()
        if best is None or total < best[2] * 0.998:
            stale = 0
        else:
            stale += 1
        if best is None or total < best[2]:
            best = (x, T.copy(), total, float(u.max()))
        if stale >= 2:
            break
        T = T * np.clip(u, 0.5, 2.0)
    if best is None:
        raise PlanningError("no feasible spline found for the box route")
    x, T, _, k = best
    T = T * max(k, 1e-9)
    if any(np.any(v) for v in (v0, v1, a0, a1)):
        # scaling time changes non-zero boundary rates: re-solve until within the limits
        for _ in range(8):
            x = qp.solve(T, bc)
            if x is None:
                raise PlanningError("no feasible spline found for the boundary states")
            k = float(_usage(x, T, v_max, a_max).max())
            if k <= 1.0:
                break
            T = T * (k * 1.001)
        else:
            raise PlanningError("could not meet the limits with the given boundary states")
    spline = Spline(points=x, durations=T, boxes=rboxes)
    return PositionPlan(spline=spline, route=route, solves=qp.solves,
                        planning_time=time.perf_counter() - t_start, lower_bound=lower,
                        iterations=qp.iterations)


__all__ = ["Spline", "PositionPlan", "plan_position", "reference_polyline", "initial_durations",
           "peak_bounds", "trapezoid_time"]
