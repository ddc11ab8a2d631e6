"""Global planner: near time-optimal, minimum-jerk piecewise Bezier spline through safe boxes.

Geometry and timing are separated. For fixed segment durations T the spline is the solution of
one convex QP (all three axes at once): minimum integrated squared jerk, every control point
inside its segment's box (so by the convex hull the whole curve is), the boundary position,
velocity and acceleration, and continuity through the jerk (C3) at the joints. No velocity or
acceleration row is in the QP: box containment does not depend on time, so any solution can
be slowed down uniformly until it meets the flight mode's limits, and that scale is computed
from a tight bound on the NORMS of velocity and acceleration (the convex hull of the
subdivided derivative curves), not a per-axis budget.

Timing: T starts from a trapezoidal speed profile along the reference polyline (with corner
speeds from the turning angles), and a handful of retiming steps stretch or shrink each
segment by its own limit usage; the best uniformly-scaled result is kept: 4-8 solves per
route instead of a duration bisection (73-127). Each solve is a Mehrotra interior-point method
on the KKT matrix reordered into a band (half width 7: a segment's points only meet their
neighbouring joints' rows), Ruiz-equilibrated, one LAPACK band LU an iteration; when it does not
converge (5 of ~1100 solves over every module pair in three flight modes) Clarabel solves the
same QP, updated in place (`update` of P, A and b on a fixed sparsity pattern). Segments follow the profile: short where the speed changes (so the piecewise curve
can hold the acceleration at its limit), up to MAX_LEG in cruise; the joints on straight legs
are pulled towards the profile's points (a quadratic tracking term), those near a corner are
left free so the curve cuts it.
The time-optimality gap is reported against the trapezoidal lower bound on the shortest
polyline through the route's boxes.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import lru_cache
from math import comb

import clarabel
import numpy as np
import scipy.sparse as sp
from scipy.linalg import lapack

from . import bezier
from .boxes import NoRoute, OutsideSafeSet, SafeSet, safe_set

DEGREE = 7
CONTINUITY = 3          # derivatives continuous at the joints (3: jerk)
BOX_EPS = 1e-6          # m, control points kept this far inside their box
MAX_LEG = 2.0           # m: cruise legs are split into segments at most this long
CORNER_REACH = 1.0      # share of the shorter leg near a corner left free (the curve cuts it)
DV_FRACTION = 0.34      # a segment changes speed by at most this share of v_max
MIN_SEGMENT_TIME = 0.2  # x v/a: shortest segment the profile makes inside a leg
MAX_SEGMENTS = 40       # split no further than this many segments in all (QP size)
RETIME_STEPS = 7        # retiming solves after the first (stops early without progress)
TRACK_WEIGHT = 1.0      # pull of the straight-leg joints to the speed profile's points
QP_TOLERANCE = 1e-7      # Clarabel gap/feasibility tolerances (default 1e-8: 3 more iterations a solve)
BANDED_TOLERANCE = 1e-9   # relative residual tolerance of the banded interior-point solver
RUIZ_STEPS = 4            # equilibration passes of the banded solver's KKT matrix
HULL_SPLITS = 2         # derivative curves subdivided 2^k times for the norm bound


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


def _falling(n: int, k: int) -> float:
    out = 1.0
    for i in range(k):
        out *= n - i
    return out


class SplineQP:
    """Minimum-jerk QP of the three axes for a fixed box route, built once, retimed by updates.

    Variables x[ax, s, i] (3 axes, S segments, degree n). Equalities: boundary position,
    velocity, acceleration; C0..C`continuity` at joints (rows scaled by the joint's mean
    duration for conditioning). Inequalities: every control point inside its box."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, degree: int = DEGREE,
                 continuity: int = CONTINUITY, joints: np.ndarray | None = None,
                 track_weight: float = 0.0):
        self.lo, self.hi = np.asarray(lo, float), np.asarray(hi, float)    # (S, 3)
        self.S = S = len(self.lo)
        self.n = n = degree
        self.N = N = n + 1
        self.c = c = continuity
        self.nx = 3 * S * N
        rows, cols, base, scl = [], [], [], []
        r = 0
        ix = lambda ax, s, i: (ax * S + s) * N + i  # noqa: E731
        for ax in range(3):
            for end in (0, 1):                  # boundary rows: k-th difference = bc_k T^k / n!/(n-k)!
                s = 0 if end == 0 else S - 1
                for k in range(3):
                    for i in range(k + 1):
                        sign = (-1) ** (k - i) if end == 0 else (-1) ** i
                        idx = i if end == 0 else n - i
                        rows.append(r); cols.append(ix(ax, s, idx)); base.append(sign * comb(k, i)); scl.append(0)
                    r += 1
            for j in range(S - 1):
                for k in range(c + 1):
                    for i in range(k + 1):       # end of segment j ...
                        rows.append(r); cols.append(ix(ax, j, n - i))
                        base.append((-1) ** i * comb(k, i)); scl.append(0 if k == 0 else 1 + 2 * (j * c + k - 1))
                    for i in range(k + 1):       # ... minus start of segment j+1
                        rows.append(r); cols.append(ix(ax, j + 1, i))
                        base.append(-((-1) ** (k - i)) * comb(k, i))
                        scl.append(0 if k == 0 else 2 + 2 * (j * c + k - 1))
                    r += 1
        self.n_eq = r
        box = np.arange(2 * self.nx)                 # x <= hi rows, then -x <= -lo rows
        rows = np.concatenate([rows, r + box])
        cols = np.concatenate([cols, box % self.nx])
        base = np.concatenate([base, np.where(box < self.nx, 1.0, -1.0)])
        scl = np.concatenate([scl, np.zeros(2 * self.nx, dtype=int)])
        self.m = r + 2 * self.nx
        ids = np.arange(1, len(rows) + 1, dtype=float)
        a = sp.csc_matrix((ids, (rows, cols)), shape=(self.m, self.nx))
        a.sort_indices()
        perm = a.data.astype(int) - 1
        self._a = a
        self._base = np.array(base, float)[perm]
        self._scl = np.array(scl)[perm]
        q = sp.kron(sp.identity(3 * S, format="csc"), sp.csc_matrix(bezier.jerk_cost_matrix(n)), format="csc")
        # tracking: w |x(joint) - reference joint|^2 at the start of every segment but the first
        self._q = np.zeros(self.nx)
        diag = np.zeros(self.nx)
        if joints is not None and track_weight > 0 and S > 1:
            wt = track_weight * float(np.abs(bezier.jerk_cost_matrix(n)).max())
            for ax in range(3):
                for s in range(1, S):
                    if not np.all(np.isfinite(joints[s])):
                        continue            # NaN: this joint is free (a corner)
                    diag[ix(ax, s, 0)] = wt
                    self._q[ix(ax, s, 0)] = -wt * joints[s, ax]
        pu = sp.triu(q + sp.diags(diag + 1e-30), format="csc")
        pu.sort_indices()
        self._p = pu
        self._p_seg = (np.repeat(np.arange(self.nx), np.diff(pu.indptr)) // N) % S
        rr = pu.indices
        cc = np.repeat(np.arange(self.nx), np.diff(pu.indptr))
        self._p_diag_track = np.where(rr == cc, diag[cc], 0.0)
        self._p_base = pu.data.copy() - self._p_diag_track
        lo_b = np.repeat(self.lo.T.reshape(-1) + BOX_EPS, N)
        hi_b = np.repeat(self.hi.T.reshape(-1) - BOX_EPS, N)
        self._box_b = np.concatenate([hi_b, -lo_b])
        self.solver: clarabel.DefaultSolver | None = None
        self.solves = 0
        self.iterations = 0             # interior-point iterations over all solves
        self.fallbacks = 0              # solves handed to Clarabel (the banded solver gave up)
        self._band_setup()

    # ---- banded interior-point solver ----------------------------------------------------
    def _band_setup(self) -> None:
        """Index maps of the KKT matrix [P A^T; A 0] with its unknowns reordered per axis as
        [start rows, segment 0's points, joint 0's rows, segment 1's points, ..., end rows]: a
        band matrix of half width n (a point meets only its own segment and the neighbouring
        joints' rows), which LAPACK factorises in O(size) (dgbtrf)."""
        S, N, c = self.S, self.N, self.c
        per_axis = self.n_eq // 3
        stride = N + c + 1
        n1 = 3 + S * N + (S - 1) * (c + 1) + 3
        self._nk = 3 * n1
        ax, rem = np.divmod(np.arange(self.nx), S * N)
        seg, i = np.divmod(rem, N)
        self._var_pos = ax * n1 + 3 + seg * stride + i
        ax, loc = np.divmod(np.arange(self.n_eq), per_axis)
        j, k = np.divmod(np.maximum(loc - 6, 0), c + 1)
        self._row_pos = ax * n1 + np.where(
            loc < 3, loc, np.where(loc < 6, 3 + (S - 1) * stride + N + (loc - 3), 3 + j * stride + N + k))
        pr = self._p.indices
        pc = np.repeat(np.arange(self.nx), np.diff(self._p.indptr))
        ar = self._a.indices
        acol = np.repeat(np.arange(self.nx), np.diff(self._a.indptr))
        self._a_eq = ar < self.n_eq
        ar, acol = ar[self._a_eq], acol[self._a_eq]
        self._p_off = pr != pc
        vp, rp = self._var_pos, self._row_pos
        rows = np.concatenate([vp[pr], vp[pc][self._p_off], rp[ar], vp[acol]])
        cols = np.concatenate([vp[pc], vp[pr][self._p_off], vp[acol], rp[ar]])
        self._bw = bw = int(np.max(np.abs(rows - cols)))
        self._band_idx = (2 * bw + rows - cols, cols)        # dgbtrf storage: a[i, j] at kl + ku + i - j
        r = np.arange(3 * bw + 1)[:, None] - 2 * bw + np.arange(self._nk)[None, :]
        self._band_row = np.clip(r, 0, self._nk - 1)           # row index of each band slot
        self._gbtrf, self._gbtrs = lapack.get_lapack_funcs(("gbtrf", "gbtrs"), (np.zeros(1),))
        self._h = np.concatenate([self._box_b[self.nx:] * -1.0, -self._box_b[:self.nx]])   # [lo; -hi]

    def _solve_banded(self, px: np.ndarray, ax_: np.ndarray, b_eq: np.ndarray,
                      max_iter: int = 50) -> np.ndarray | None:
        """min 1/2 x'Px + q'x, Ax = b, lo <= x <= hi by a Mehrotra predictor-corrector
        interior-point method whose Newton systems are the banded KKT matrix plus the barrier
        diagonal (one dgbtrf and two dgbtrs an iteration). x, or None if it does not converge
        (the caller falls back to Clarabel)."""
        bw, nk, nx = self._bw, self._nk, self.nx
        vp, rp = self._var_pos, self._row_pos
        ab0 = np.zeros((3 * bw + 1, nk))
        ab0[self._band_idx] = np.concatenate([px, px[self._p_off], ax_[self._a_eq], ax_[self._a_eq]])
        # Ruiz equilibration of the symmetric KKT matrix: unknowns scaled so that every row and
        # column peaks near 1 (segment durations spread the jerk weights over decades)
        sc = np.ones(nk)
        for _ in range(RUIZ_STEPS):
            col = np.abs(ab0 * sc[self._band_row] * sc).max(axis=0)
            sc /= np.sqrt(np.where(col > 0, col, 1.0))
        ab0 *= sc[self._band_row] * sc
        K = sp.dia_matrix((ab0[bw:], np.arange(bw, -bw - 1, -1)), shape=(nk, nk)).tocsr()
        dx_, dy_ = sc[vp], sc[rp]                        # x = dx_ * x~, y = dy_ * y~
        q = self._q * dx_
        b_eq = b_eq * dy_
        lo, hi = self._h[:nx] / dx_, -self._h[nx:] / dx_
        h = np.concatenate([lo, -hi])
        x = 0.5 * (lo + hi)
        s = np.concatenate([x - lo, hi - x])                  # slacks of [x >= lo; -x >= -hi]
        pdiag = np.abs(ab0[2 * bw, vp])
        z = np.full(2 * nx, max(1.0, 1e-2 * float(np.max(np.abs(q))),
                                1e-2 * float(pdiag.max()) * float(np.mean(hi - lo))))
        y = np.zeros(self.n_eq)
        kz = np.zeros(nk)
        tol_d = BANDED_TOLERANCE * (1.0 + float(np.max(np.abs(q))))
        tol_p = BANDED_TOLERANCE * (1.0 + max(float(np.max(np.abs(b_eq))), float(np.max(np.abs(h)))))
        xx = np.empty(2 * nx)                    # [x; -x]
        ds = np.empty(2 * nx)
        rhs = np.zeros(nk)

        def newton(rc: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            v = (rc + z * rg) / s
            rhs[vp] = -rd - (v[:nx] - v[nx:])
            sol = self._gbtrs(lu, bw, bw, rhs[:, None], piv)[0][:, 0]
            dx = sol[vp]
            np.add(dx, rg[:nx], out=ds[:nx])
            np.subtract(rg[nx:], dx, out=ds[nx:])
            return dx, sol[rp], -(rc + z * ds) / s

        def step(v: np.ndarray, dv: np.ndarray) -> float:
            """Largest a <= 1 with v + a dv >= 0."""
            r = np.divide(v, -dv, out=np.full_like(v, np.inf), where=dv < 0)
            return min(1.0, float(r.min()))

        for it in range(max_iter):
            kz[vp], kz[rp] = x, y
            kz = K @ kz
            rd = kz[vp] + q - (z[:nx] - z[nx:])
            rpv = kz[rp] - b_eq
            xx[:nx], xx[nx:] = x, -x
            rg = xx - s - h
            mu = float(s @ z) / (2 * nx)
            if (np.max(np.abs(rd)) <= tol_d and np.max(np.abs(rpv)) <= tol_p
                    and np.max(np.abs(rg)) <= tol_p and mu <= 1e-2 * tol_d):
                self.iterations += it
                return x * dx_
            ab = ab0.copy()
            ab[2 * bw, vp] += (z[:nx] / s[:nx] + z[nx:] / s[nx:])
            lu, piv, info = self._gbtrf(ab, bw, bw, overwrite_ab=1)
            if info != 0:
                return None
            rhs[rp] = -rpv
            sz = s * z
            dx, dy, dz = newton(sz)                                          # predictor
            ap, ad = step(s, ds), step(z, dz)
            sigma = (float((s + ap * ds) @ (z + ad * dz)) / (2 * nx) / mu) ** 3
            dx, dy, dz = newton(sz + ds * dz - sigma * mu)                   # corrector
            ap, ad = 0.99 * step(s, ds), 0.99 * step(z, dz)
            x = x + ap * dx
            s = s + ap * ds
            y = y + ad * dy
            z = z + ad * dz
            if not (np.isfinite(x @ x) and np.isfinite(z @ z)) or (ap < 1e-6 and ad < 1e-6):
                return None
        return None

    def _scales(self, T: np.ndarray) -> np.ndarray:
        out = np.ones(1 + 2 * (self.S - 1) * self.c)
        if self.S > 1:
            w = 0.5 * (T[:-1] + T[1:])
            k = np.arange(1, self.c + 1)
            out[1::2] = ((w / T[:-1])[:, None] ** k).reshape(-1)
            out[2::2] = ((w / T[1:])[:, None] ** k).reshape(-1)
        return out

    def _b(self, T: np.ndarray, bc: np.ndarray) -> np.ndarray:
        """bc (3, 6): per axis [p0, v0, a0, p1, v1, a1]."""
        eq = np.zeros(self.n_eq)
        per_axis = self.n_eq // 3
        n = self.n
        for ax in range(3):
            o = ax * per_axis
            for end, Te in ((0, T[0]), (1, T[-1])):
                for k in range(3):
                    eq[o + 3 * end + k] = bc[ax, 3 * end + k] * Te ** k / _falling(n, k)
        return np.concatenate([eq, self._box_b])

    def solve(self, T: np.ndarray, bc: np.ndarray) -> np.ndarray | None:
        """Control points (S, n+1, 3) for durations T and boundary values bc (3, 6), or None."""
        T = np.asarray(T, dtype=float)
        tm = float(np.mean(T))
        px = self._p_base * (tm / T[self._p_seg]) ** 5 + self._p_diag_track
        ax = self._base * self._scales(T)[self._scl]
        b = self._b(T, np.asarray(bc, float))
        self.solves += 1
        x = self._solve_banded(px, ax, b[:self.n_eq])
        if x is not None:
            x = x.reshape(3, self.S, self.N).transpose(1, 2, 0)
            return np.clip(x, self.lo[:, None, :], self.hi[:, None, :])
        self.fallbacks += 1
        if self.solver is None:
            st = clarabel.DefaultSettings()
            st.verbose = False
            st.presolve_enable = False
            st.max_iter = 100
            st.tol_gap_abs = st.tol_gap_rel = st.tol_feas = QP_TOLERANCE
            p = self._p.copy(); p.data = px
            a = self._a.copy(); a.data = ax
            self.solver = clarabel.DefaultSolver(
                p, self._q, a, b,
                [clarabel.ZeroConeT(self.n_eq), clarabel.NonnegativeConeT(self.m - self.n_eq)], st)
        else:
            self.solver.update(P=px, A=ax, b=b)
        res = self.solver.solve()
        self.iterations += int(res.iterations)
        if str(res.status) not in ("Solved", "AlmostSolved") or res.x is None or len(res.x) != self.nx:
            return None
        x = np.asarray(res.x).reshape(3, self.S, self.N).transpose(1, 2, 0)
        if not np.all(np.isfinite(x)):
            return None
        x = np.clip(x, self.lo[:, None, :], self.hi[:, None, :])   # interior-point rounding
        return x


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


__all__ = ["PlanningError", "Spline", "SplineQP", "PositionPlan", "plan_position", "NoRoute",
           "OutsideSafeSet", "reference_polyline", "initial_durations", "peak_bounds",
           "trapezoid_time"]
