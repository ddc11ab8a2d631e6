"""Minimum-jerk QP of a piecewise Bezier spline through a fixed box route, and its solver.

For fixed segment durations T the spline is the solution of one convex QP (all three axes at
once): minimum integrated squared jerk, every control point inside its segment's box, the
boundary position, velocity and acceleration, and continuity through the jerk (C3) at the
joints. Each solve is a Mehrotra interior-point method on the KKT matrix reordered into a band
(half width 7: a segment's points only meet their neighbouring joints' rows), Ruiz-equilibrated,
one LAPACK band LU an iteration; when it does not converge (5 of ~1100 solves over every module
pair in three flight modes) Clarabel solves the same QP, updated in place (`update` of P, A and
b on a fixed sparsity pattern). position_planner.py chooses the durations.
"""
from __future__ import annotations

from math import comb

import clarabel
import numpy as np
import scipy.sparse as sp
from scipy.linalg import lapack

from astrobee import bezier

DEGREE = 7
CONTINUITY = 3          # derivatives continuous at the joints (3: jerk)
BOX_EPS = 1e-6          # m, control points kept this far inside their box
QP_TOLERANCE = 1e-7      # Clarabel gap/feasibility tolerances (default 1e-8: 3 more iterations a solve)
BANDED_TOLERANCE = 1e-9   # relative residual tolerance of the banded interior-point solver
RUIZ_STEPS = 4            # equilibration passes of the banded solver's KKT matrix


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


__all__ = ["SplineQP", "DEGREE", "CONTINUITY"]
