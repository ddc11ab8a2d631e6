"""Global planner: time-optimal, minimum-jerk piecewise Bezier spline through safe boxes.

One Bezier segment (degree 7) per box of the route; every control point inside its box, so by
the convex-hull property the whole segment is. Joints are continuous through the acceleration
(C2): the controller feeds the reference acceleration forward as a force, so a C2 reference
gives a continuous commanded force; a jerk step at a joint only changes the force's slope, and
minimising the integrated squared jerk keeps those steps small.

Limits. The flight mode's limits are on the velocity and acceleration NORMS. We use a per-axis
box on the control points of the derivative curves (a sufficient condition by the convex hull)
with a per-segment split of the budget: |v_x| <= v sqrt(w_x), ... with w_x + w_y + w_z = 1,
so the box lies inside the ball of radius v. The split follows the direction of travel of
the segment (reference polyline leg), which in the axis-aligned ISS corridors gives ~0.96 v
along the corridor instead of the uniform v/sqrt(3); it is refined from the solution's per-axis
usage. The split makes the QP separable: three independent 1-D QPs (one per axis).

Solver. The QP of each axis is built once per route (Clarabel, interior point) and retimed by
`update` of the values of P and A (same sparsity pattern) and of b; no re-canonicalisation.
OSQP (ADMM) was tried first and did not converge in 10,000 iterations on these problems (the
1/T^5 jerk weights and the mm-scale acceleration rows make them badly conditioned), while the
interior-point solver takes ~10-30 iterations and detects infeasibility reliably, which the
time bisection depends on.

Time minimisation: bisection on a global time scale (per axis; the plan's scale is the largest
axis scale), then rounds of per-segment shrinking of the segments with slack and re-splitting
the per-axis budgets, each followed by a new bisection; a round is kept only if the total
duration drops.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import clarabel
import numpy as np
import scipy.sparse as sp

from . import bezier
from .boxes import NoRoute, OutsideSafeSet, SafeSet, safe_set

DEGREE = 7
BOX_EPS = 1e-6          # m, control points kept this far inside their box
LIMIT_EPS = 1e-3        # relative margin on the limits inside the QP
BUDGET_FLOOR = 0.03     # minimum share of the squared-norm budget an axis gets
MAX_LEG = 1.0         # m: longer polyline legs are split into several segments in their box
MAX_SPLIT = 6           # at most this many segments per box
MAX_SEGMENTS = 20       # split no further than this many segments in all (planning time)


class PlanningError(RuntimeError):
    """The planner could not find a trajectory (message says why)."""


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
        """k-th time derivative at times t, shape (len(t), 3)."""
        idx, s = self.locate(t)
        n = self.points.shape[1] - 1
        out = np.zeros((len(s), 3))
        if k > n:
            return out
        for seg in np.unique(idx):
            m = idx == seg
            cps = bezier.derivative_points(self.points[seg], self.durations[seg], k)
            out[m] = bezier.evaluate(cps, s[m])
        return out

    def scaled(self, factor: float) -> "Spline":
        """The same path slowed down by `factor` (durations times factor)."""
        return Spline(self.points.copy(), self.durations * factor, self.boxes.copy())


class AxisQP:
    """Minimum-jerk QP of one axis for a fixed box route, built once, retimed by updates.

    Variables: control points x[s, i] (S segments, degree n). Equalities: boundary position,
    velocity, acceleration; C0/C1/C2 at joints. Inequalities: box, velocity and acceleration
    limits on the derivative control points (per segment)."""

    # entry scale types (value = base * factor(type, k))
    CONST, VEL, ACC, JA, JB, JA2, JB2 = range(7)

    def __init__(self, lo: np.ndarray, hi: np.ndarray, degree: int = DEGREE):
        self.lo, self.hi = np.asarray(lo, float), np.asarray(hi, float)
        self.S = S = len(self.lo)
        self.n = n = degree
        self.N = N = n + 1
        self.nx = S * N
        rows, cols, base, typ, key = [], [], [], [], []
        r = 0

        def row(entries, t=0, k=0):
            nonlocal r
            for c, b in entries:
                rows.append(r); cols.append(c); base.append(b); typ.append(t); key.append(k)
            r += 1

        ix = lambda s, i: s * N + i  # noqa: E731
        L = S - 1
        # equalities: boundary conditions
        row([(ix(0, 0), 1.0)])
        row([(ix(0, 1), 1.0), (ix(0, 0), -1.0)], self.VEL, 0)
        row([(ix(0, 2), 1.0), (ix(0, 1), -2.0), (ix(0, 0), 1.0)], self.ACC, 0)
        row([(ix(L, n), 1.0)])
        row([(ix(L, n), 1.0), (ix(L, n - 1), -1.0)], self.VEL, L)
        row([(ix(L, n), 1.0), (ix(L, n - 1), -2.0), (ix(L, n - 2), 1.0)], self.ACC, L)
        # joints
        for j in range(S - 1):
            row([(ix(j, n), 1.0), (ix(j + 1, 0), -1.0)])
            for c, b, t in ((ix(j, n), 1.0, self.JA), (ix(j, n - 1), -1.0, self.JA),
                            (ix(j + 1, 1), -1.0, self.JB), (ix(j + 1, 0), 1.0, self.JB)):
                rows.append(r); cols.append(c); base.append(b); typ.append(t); key.append(j)
            r += 1
            for c, b, t in ((ix(j, n), 1.0, self.JA2), (ix(j, n - 1), -2.0, self.JA2),
                            (ix(j, n - 2), 1.0, self.JA2), (ix(j + 1, 2), -1.0, self.JB2),
                            (ix(j + 1, 1), 2.0, self.JB2), (ix(j + 1, 0), -1.0, self.JB2)):
                rows.append(r); cols.append(c); base.append(b); typ.append(t); key.append(j)
            r += 1
        self.n_eq = r
        # inequalities A x <= b: box, velocity, acceleration (upper then lower)
        for sign in (1.0, -1.0):
            for s in range(S):
                for i in range(N):
                    row([(ix(s, i), sign)])
        self.r_vel = r
        for sign in (1.0, -1.0):
            for s in range(S):
                for i in range(n):
                    row([(ix(s, i + 1), sign), (ix(s, i), -sign)], self.VEL, s)
        self.r_acc = r
        for sign in (1.0, -1.0):
            for s in range(S):
                for i in range(n - 1):
                    row([(ix(s, i + 2), sign), (ix(s, i + 1), -2 * sign), (ix(s, i), sign)], self.ACC, s)
        self.m = r
        ids = np.arange(1, len(rows) + 1, dtype=float)
        a = sp.csc_matrix((ids, (rows, cols)), shape=(self.m, self.nx))
        a.sort_indices()
        self._perm = a.data.astype(int) - 1
        self._a = a
        self._base = np.array(base)
        self._typ = np.array(typ)
        self._key = np.array(key)
        q = sp.block_diag([sp.csc_matrix(bezier.jerk_cost_matrix(n))] * S, format="csc")
        pu = sp.triu(q, format="csc")
        pu.sort_indices()
        self._p = pu
        self._p_base = pu.data.copy()
        self._p_seg = np.repeat(np.arange(self.nx), np.diff(pu.indptr)) // N
        self.solver: clarabel.DefaultSolver | None = None
        self.solves = 0

    def _a_values(self, T: np.ndarray) -> np.ndarray:
        n = self.n
        f = np.ones(len(self._base))
        t, k = self._typ, self._key
        f = np.where(t == self.VEL, n / T[k], f)
        f = np.where(t == self.ACC, n * (n - 1) / T[k] ** 2, f)
        if self.S > 1:
            Ta, Tb = T[:-1], T[1:]
            kj = np.minimum(k, self.S - 2)
            w = 0.5 * (Ta + Tb)
            f = np.where(t == self.JA, (w / Ta)[kj], f)
            f = np.where(t == self.JB, (w / Tb)[kj], f)
            f = np.where(t == self.JA2, ((w / Ta) ** 2)[kj], f)
            f = np.where(t == self.JB2, ((w / Tb) ** 2)[kj], f)
        return (self._base * f)[self._perm]

    def _b(self, bc: np.ndarray, vlim: np.ndarray, alim: np.ndarray) -> np.ndarray:
        S, N, n = self.S, self.N, self.n
        eq = np.zeros(self.n_eq)
        eq[:6] = bc
        hi = np.repeat(self.hi - BOX_EPS, N)
        lo = np.repeat(self.lo + BOX_EPS, N)
        vb = np.repeat(vlim * (1 - LIMIT_EPS), n)
        ab = np.repeat(alim * (1 - LIMIT_EPS), n - 1)
        return np.concatenate([eq, hi, -lo, vb, vb, ab, ab])

    def solve(self, T: np.ndarray, bc: np.ndarray, vlim: np.ndarray, alim: np.ndarray
              ) -> np.ndarray | None:
        """Control points (S, n+1) for durations T, boundary values bc = [p0, v0, a0, p1, v1, a1]
        and per-segment limits, or None when infeasible."""
        T = np.asarray(T, dtype=float)
        tm = float(np.mean(T))
        px = self._p_base * (tm / T[self._p_seg]) ** 5
        ax = self._a_values(T)
        b = self._b(np.asarray(bc, float), np.asarray(vlim, float), np.asarray(alim, float))
        self.solves += 1
        if self.solver is None:
            st = clarabel.DefaultSettings()
            st.verbose = False
            st.presolve_enable = False
            st.max_iter = 100
            p = self._p.copy(); p.data = px
            a = self._a.copy(); a.data = ax
            self.solver = clarabel.DefaultSolver(
                p, np.zeros(self.nx), a, b,
                [clarabel.ZeroConeT(self.n_eq), clarabel.NonnegativeConeT(self.m - self.n_eq)], st)
        else:
            self.solver.update(P=px, A=ax, b=b)
        res = self.solver.solve()
        status = str(res.status)
        if "Infeasible" in status or res.x is None or len(res.x) != self.nx:
            return None
        # other statuses (e.g. InsufficientProgress) are kept when the point passes the check
        x = np.asarray(res.x).reshape(self.S, self.N)
        if not np.all(np.isfinite(x)):
            return None
        return x if self.check(x, T, bc, vlim, alim) else None

    def check(self, x: np.ndarray, T: np.ndarray, bc: np.ndarray, vlim: np.ndarray,
              alim: np.ndarray, tol: float = 1e-7) -> bool:
        """Box, limits and boundary values hold on the control points (true limits)."""
        if np.any(x < self.lo[:, None] - tol) or np.any(x > self.hi[:, None] + tol):
            return False
        n = self.n
        v = n * np.diff(x, axis=1) / T[:, None]
        a = n * (n - 1) * np.diff(x, 2, axis=1) / T[:, None] ** 2
        if np.any(np.abs(v) > vlim[:, None] + tol) or np.any(np.abs(a) > alim[:, None] + tol):
            return False
        ends = np.array([x[0, 0], v[0, 0], a[0, 0], x[-1, -1], v[-1, -1], a[-1, -1]])
        return bool(np.all(np.abs(ends - bc) <= 1e-6 * np.maximum(1.0, np.abs(bc))))


def reference_polyline(route_boxes: np.ndarray, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """[start, w_1, ..., w_{S-1}, goal] with w_i in the overlap of boxes i-1 and i, shortening the
    polyline by projected Gauss-Seidel on the sum of squared legs."""
    S = len(route_boxes)
    ov = [np.concatenate([np.maximum(route_boxes[i, :3], route_boxes[i + 1, :3]),
                          np.minimum(route_boxes[i, 3:], route_boxes[i + 1, 3:])]) for i in range(S - 1)]
    pts = np.array([start] + [0.5 * (o[:3] + o[3:]) for o in ov] + [goal], dtype=float)
    for _ in range(80):
        for i in range(1, S):
            o = ov[i - 1]
            pts[i] = np.clip(0.5 * (pts[i - 1] + pts[i + 1]), o[:3], o[3:])
    return pts


def split_long_legs(route: list[int], rboxes: np.ndarray, poly: np.ndarray, max_leg: float
                    ) -> tuple[list[int], np.ndarray, np.ndarray]:
    """Split polyline legs longer than max_leg into equal segments in the same box: one degree-7
    segment per long box cannot follow a trapezoidal speed profile inside its convex-hull
    limits, several can (e.g. 6 m in one box: 72 s as one segment, ~52 s as four)."""
    if not np.isfinite(max_leg) or max_leg <= 0:
        return route, rboxes, poly
    legs = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    k = np.clip(np.ceil(legs / max_leg).astype(int), 1, MAX_SPLIT)
    while k.sum() > max(MAX_SEGMENTS, len(legs)):     # keep the QP small on long routes
        max_leg *= 1.25
        k = np.clip(np.ceil(legs / max_leg).astype(int), 1, MAX_SPLIT)
    if np.all(k == 1):
        return route, rboxes, poly
    new_route, new_boxes, pts = [], [], [poly[0]]
    for s, ks in enumerate(k):
        for j in range(1, ks + 1):
            pts.append(poly[s] + (poly[s + 1] - poly[s]) * j / ks)
            new_route.append(route[s])
            new_boxes.append(rboxes[s])
    return new_route, np.array(new_boxes), np.array(pts)


def initial_durations(poly: np.ndarray, v: float, a: float) -> np.ndarray:
    """Segment durations from a trapezoidal speed profile (v, a) along the polyline."""
    legs = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(legs)])
    L = s[-1]
    if L < 1e-9:
        return np.full(len(legs), 1.0)
    vp = min(v, np.sqrt(L * a))
    d_acc = 0.5 * vp * vp / a
    t_acc = vp / a
    t_cruise = (L - 2 * d_acc) / vp
    t = np.where(s < d_acc, np.sqrt(2 * np.maximum(s, 0) / a),
                 np.where(s <= L - d_acc, t_acc + (s - d_acc) / vp,
                          2 * t_acc + t_cruise - np.sqrt(2 * np.maximum(L - s, 0) / a)))
    return np.maximum(np.diff(t), 0.02 * t[-1] / len(legs) + 1e-2)


def direction_budgets(poly: np.ndarray) -> np.ndarray:
    """(S, 3) per-axis shares of the squared-norm budget from each leg's direction (rows sum to 1),
    smoothed with the neighbouring legs so corner segments get both axes."""
    legs = np.diff(poly, axis=0)
    d = legs / np.maximum(np.linalg.norm(legs, axis=1, keepdims=True), 1e-9)
    w = d ** 2
    if len(w) > 1:
        ws = w.copy()
        ws[1:] += 0.5 * w[:-1]
        ws[:-1] += 0.5 * w[1:]
        w = ws
    return _normalise_budget(w)


def _normalise_budget(w: np.ndarray) -> np.ndarray:
    w = w / w.sum(axis=1, keepdims=True)
    w = (w + BUDGET_FLOOR) / (1.0 + 3 * BUDGET_FLOOR)
    return w / w.sum(axis=1, keepdims=True)


@dataclass
class PositionPlan:
    spline: Spline
    route: list[int]
    solves: int
    planning_time: float


class _Problem:
    """The three axis QPs of one route with boundary conditions and budgets."""

    def __init__(self, rboxes, start, goal, v0, v1, a0, a1, v_max, a_max, degree):
        self.qps = [AxisQP(rboxes[:, ax], rboxes[:, ax + 3], degree) for ax in range(3)]
        self.bc = [np.array([start[ax], v0[ax], a0[ax], goal[ax], v1[ax], a1[ax]]) for ax in range(3)]
        self.v_max, self.a_max = v_max, a_max

    def solve_axis(self, ax, T, w):
        return self.qps[ax].solve(T, self.bc[ax], self.v_max * np.sqrt(w[:, ax]),
                                  self.a_max * np.sqrt(w[:, ax]))

    def bisect(self, T: np.ndarray, w: np.ndarray, rel_tol: float = 0.005
               ) -> tuple[float, np.ndarray]:
        """Smallest global scale (to rel_tol) at which all axes are feasible; (alpha, x (S,N,3))."""
        alphas, xs = [], []
        for ax in range(3):
            alphas.append(self._bisect_axis(ax, T, w, rel_tol))
        alpha = max(a for a, _ in alphas)
        for _ in range(20):
            xs = [self.solve_axis(ax, alpha * T, w) if alphas[ax][0] != alpha else alphas[ax][1]
                  for ax in range(3)]
            if all(x is not None for x in xs):
                return alpha, np.stack(xs, axis=-1)
            alpha *= 1.0 + rel_tol
        raise PlanningError("no feasible timing found for the box route")

    def _bisect_axis(self, ax, T, w, rel_tol):
        x = self.solve_axis(ax, T, w)
        if x is None:
            lo, hi = 1.0, 2.0
            for _ in range(25):
                x = self.solve_axis(ax, hi * T, w)
                if x is not None:
                    break
                lo, hi = hi, hi * 2.0
            else:
                raise PlanningError("no feasible timing found for the box route")
        else:
            lo, hi = 0.5, 1.0
            for _ in range(25):
                x2 = self.solve_axis(ax, lo * T, w)
                if x2 is None:
                    break
                hi, x = lo, x2
                lo *= 0.5
        best = x
        while hi - lo > rel_tol * hi:
            mid = 0.5 * (lo + hi)
            x2 = self.solve_axis(ax, mid * T, w)
            if x2 is None:
                lo = mid
            else:
                hi, best = mid, x2
        return hi, best

    def usage(self, x: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per segment and axis: peak |v|/v_max and peak |a|/a_max on the control points."""
        n = x.shape[1] - 1
        v = np.abs(n * np.diff(x, axis=1) / T[:, None, None]).max(axis=1) / self.v_max
        a = np.abs(n * (n - 1) * np.diff(x, 2, axis=1) / T[:, None, None] ** 2).max(axis=1) / self.a_max
        return v, a

    @property
    def solves(self) -> int:
        return sum(q.solves for q in self.qps)


def plan_position(start: np.ndarray, goal: np.ndarray, v_max: float, a_max: float,
                  safe: SafeSet | None = None, v0: np.ndarray | None = None,
                  v1: np.ndarray | None = None, a0: np.ndarray | None = None,
                  a1: np.ndarray | None = None, refine_rounds: int = 4,
                  degree: int = DEGREE, max_leg: float = MAX_LEG) -> PositionPlan:
    """Time-optimal (for the limits) minimum-jerk spline from start to goal inside `safe`.
    Boundary velocity/acceleration default to rest. Raises OutsideSafeSet, NoRoute, PlanningError."""
    t_start = time.perf_counter()
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    z = np.zeros(3)
    v0, v1, a0, a1 = (z if v is None else np.asarray(v, float) for v in (v0, v1, a0, a1))
    for name, v in (("start", start), ("goal", goal), ("v0", v0), ("v1", v1), ("a0", a0), ("a1", a1)):
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ValueError(f"{name} must be a finite 3-vector")
    if not (v_max > 0 and a_max > 0):
        raise PlanningError("the flight mode's velocity/acceleration limits are zero")
    safe = safe_set() if safe is None else safe
    route = safe.route(start, goal)
    rboxes = safe.boxes[route]
    poly = reference_polyline(rboxes, start, goal)
    route, rboxes, poly = split_long_legs(route, rboxes, poly, max_leg)
    T = initial_durations(poly, v_max, a_max)
    w = direction_budgets(poly)
    prob = _Problem(rboxes, start, goal, v0, v1, a0, a1, v_max, a_max, degree)
    alpha, x = prob.bisect(T, w)
    T = alpha * T
    for _ in range(refine_rounds):
        uv, ua = prob.usage(x, T)
        # per-axis budget from what the solution needs (squared shares), blended with the old
        need = np.maximum(uv, np.sqrt(ua)) ** 2
        w_new = _normalise_budget(0.5 * w + 0.5 * need / np.maximum(need.sum(1, keepdims=True), 1e-12))
        seg_u = np.max(np.maximum(uv / np.sqrt(w), np.sqrt(ua / w)), axis=1)
        Tn = T * np.clip(seg_u + 0.02, 0.5, 1.0)
        try:
            a2, x2 = prob.bisect(Tn, w_new)
        except PlanningError:
            break
        if a2 * Tn.sum() < T.sum() * 0.995:
            T, x, w = a2 * Tn, x2, w_new
        else:
            break
    spline = Spline(points=x, durations=T, boxes=rboxes)
    return PositionPlan(spline=spline, route=route, solves=prob.solves,
                        planning_time=time.perf_counter() - t_start)


__all__ = ["PlanningError", "Spline", "AxisQP", "PositionPlan", "plan_position", "NoRoute",
           "OutsideSafeSet", "reference_polyline", "initial_durations", "direction_budgets"]
