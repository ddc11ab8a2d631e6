"""The grasp's per-step work on the mass-spring bag as compiled loops (numba): one pass over the
held nodes instead of a dozen small numpy calls a step (the strap cost ~20% of a 412-node step
before; MassSpring keeps the numpy formulas for machines without numba, tested equal).

- `hold_rhs`: the tethers' explicit spring terms (astrobee_sim.grasp's strap and hinge: a node
  group's centroid pulled to a point) and the strap's twist spring (the formulas of
  grasp.twist_forces), added to the step's right-hand side; returns the twist torques;
- `tether_pull`: each tether's force on what holds it (the gripper);
- `lowrank_update`: the Woodbury correction of the tethers' solve, y -= Z S (W y), W y being
  the groups' centroids of y.

Node groups are packed as CSR rows (`pack_groups`: nodes, ptr). Every copy k of (N, K, 3)
arrays is summed with the same arithmetic, so equal copies stay equal.
"""
from __future__ import annotations

import math

import numpy as np

try:
    from numba import njit
except ImportError:          # numba missing: MassSpring's numpy formulas
    njit = None


def pack_groups(groups: list) -> tuple[np.ndarray, np.ndarray]:
    """(nodes, ptr): group g's nodes are nodes[ptr[g]:ptr[g + 1]] (int64, contiguous)."""
    sizes = [len(g) for g in groups]
    nodes = (np.concatenate([np.asarray(g, dtype=np.int64) for g in groups]) if groups
             else np.zeros(0, np.int64))
    ptr = np.zeros(len(groups) + 1, np.int64)
    ptr[1:] = np.cumsum(sizes)
    return np.ascontiguousarray(nodes), ptr


def _centroid(y, nodes, lo, hi, b):  # pragma: no cover - compiled
    """Mean of y[nodes[lo:hi], b, :] as three floats."""
    m0 = m1 = m2 = 0.0
    for p in range(lo, hi):
        i = nodes[p]
        m0 += y[i, b, 0]
        m1 += y[i, b, 1]
        m2 += y[i, b, 2]
    inv = 1.0 / (hi - lo)
    return m0 * inv, m1 * inv, m2 * inv


def _spread(rhs, nodes, lo, hi, b, f0, f1, f2):  # pragma: no cover - compiled
    """rhs[nodes[lo:hi], b] += (f0, f1, f2)."""
    for p in range(lo, hi):
        i = nodes[p]
        rhs[i, b, 0] += f0
        rhs[i, b, 1] += f1
        rhs[i, b, 2] += f2


def _hold_rhs_loop(rhs, x, v, h, gn, gp, gk, gc, tt, tv, wn, wp, wk, wc,
                   frames):  # pragma: no cover - compiled
    """rhs (N, K, 3) += h * (tether terms + twist forces), in place; returns the twist torques
    on the grippers (T, K, 3).

    Tethers (G groups gn/gp, stiffness gk, damping gc, targets tt and their velocities tv,
    (G, K, 3)): each of a group's n nodes gets (k (target - centroid) + c target_vel) / n.
    Twists (T springs: groups 2t and 2t + 1 of wn/wp are the strap's halves a and b; wk, wc;
    frames (T, K, 9) = the handle normal n, the strap's rest axis u, the gripper's angular
    velocity): grasp.twist_forces' torque -(k angle + c rate) n on the span e = mean(a) -
    mean(b), as a force fa on a's centroid and -fa on b's."""
    kk = x.shape[1]
    for g in range(gp.shape[0] - 1):
        lo, hi = gp[g], gp[g + 1]
        s = h / (hi - lo)
        for b in range(kk):
            m0, m1, m2 = _centroid(x, gn, lo, hi, b)
            _spread(rhs, gn, lo, hi, b,
                    s * (gk[g] * (tt[g, b, 0] - m0) + gc[g] * tv[g, b, 0]),
                    s * (gk[g] * (tt[g, b, 1] - m1) + gc[g] * tv[g, b, 1]),
                    s * (gk[g] * (tt[g, b, 2] - m2) + gc[g] * tv[g, b, 2]))
    nt = wk.shape[0]
    tau = np.zeros((nt, kk, 3))
    for t in range(nt):
        alo, ahi, blo, bhi = wp[2 * t], wp[2 * t + 1], wp[2 * t + 1], wp[2 * t + 2]
        for b in range(kk):
            a0, a1, a2 = _centroid(x, wn, alo, ahi, b)
            b0, b1, b2 = _centroid(x, wn, blo, bhi, b)
            e0, e1, e2 = a0 - b0, a1 - b1, a2 - b2
            a0, a1, a2 = _centroid(v, wn, alo, ahi, b)
            b0, b1, b2 = _centroid(v, wn, blo, bhi, b)
            d0, d1, d2 = a0 - b0, a1 - b1, a2 - b2
            n0, n1, n2 = frames[t, b, 0], frames[t, b, 1], frames[t, b, 2]
            u0, u1, u2 = frames[t, b, 3], frames[t, b, 4], frames[t, b, 5]
            en = e0 * n0 + e1 * n1 + e2 * n2
            p0, p1, p2 = e0 - en * n0, e1 - en * n1, e2 - en * n2
            ang = math.atan2((u1 * p2 - u2 * p1) * n0 + (u2 * p0 - u0 * p2) * n1
                             + (u0 * p1 - u1 * p0) * n2, u0 * p0 + u1 * p1 + u2 * p2)
            ee = max(e0 * e0 + e1 * e1 + e2 * e2, 1e-12)
            rate = (((e1 * d2 - e2 * d1) * n0 + (e2 * d0 - e0 * d2) * n1
                     + (e0 * d1 - e1 * d0) * n2) / ee
                    - (frames[t, b, 6] * n0 + frames[t, b, 7] * n1 + frames[t, b, 8] * n2))
            s = -(wk[t] * ang + wc[t] * rate) / ee
            f0, f1, f2 = s * (n1 * e2 - n2 * e1), s * (n2 * e0 - n0 * e2), s * (n0 * e1 - n1 * e0)
            sa, sb = h / (ahi - alo), h / (bhi - blo)
            _spread(rhs, wn, alo, ahi, b, sa * f0, sa * f1, sa * f2)
            _spread(rhs, wn, blo, bhi, b, -sb * f0, -sb * f1, -sb * f2)
            tau[t, b, 0] = -(e1 * f2 - e2 * f1)
            tau[t, b, 1] = -(e2 * f0 - e0 * f2)
            tau[t, b, 2] = -(e0 * f1 - e1 * f0)
    return tau


def _tether_pull_loop(x, v, gn, gp, gk, gc, tt, tv):  # pragma: no cover - compiled
    """(G, K, 3): k (centroid - target) + c (centroid velocity - target velocity) per tether."""
    kk = x.shape[1]
    out = np.empty((gp.shape[0] - 1, kk, 3))
    for g in range(gp.shape[0] - 1):
        for b in range(kk):
            m0, m1, m2 = _centroid(x, gn, gp[g], gp[g + 1], b)
            w0, w1, w2 = _centroid(v, gn, gp[g], gp[g + 1], b)
            out[g, b, 0] = gk[g] * (m0 - tt[g, b, 0]) + gc[g] * (w0 - tv[g, b, 0])
            out[g, b, 1] = gk[g] * (m1 - tt[g, b, 1]) + gc[g] * (w1 - tv[g, b, 1])
            out[g, b, 2] = gk[g] * (m2 - tt[g, b, 2]) + gc[g] * (w2 - tv[g, b, 2])
    return out


def _lowrank_loop(y, z, s, gn, gp):  # pragma: no cover - compiled
    """y (N, C) -= z (N, G) @ (s (G, G) @ (the groups' centroids of y, (G, C))), in place."""
    ng, nc = gp.shape[0] - 1, y.shape[1]
    t = np.zeros((ng, nc))
    for g in range(ng):
        for p in range(gp[g], gp[g + 1]):
            for c in range(nc):
                t[g, c] += y[gn[p], c]
        inv = 1.0 / (gp[g + 1] - gp[g])
        for c in range(nc):
            t[g, c] *= inv
    cor = np.zeros((ng, nc))
    for i in range(ng):
        for j in range(ng):
            for c in range(nc):
                cor[i, c] += s[i, j] * t[j, c]
    for n in range(y.shape[0]):
        for i in range(ng):
            zi = z[n, i]
            for c in range(nc):
                y[n, c] -= zi * cor[i, c]


if njit is not None:
    _centroid = njit(inline="always")(_centroid)
    _spread = njit(inline="always")(_spread)
    hold_rhs = njit(cache=True)(_hold_rhs_loop)
    tether_pull = njit(cache=True)(_tether_pull_loop)
    lowrank_update = njit(cache=True)(_lowrank_loop)
else:
    hold_rhs = tether_pull = lowrank_update = None


def warm_up() -> None:
    """Load (or compile once per machine) the loops outside any timed step."""
    if hold_rhs is None:
        return
    z3, i1, f1 = np.zeros((2, 1, 3)), np.array([0, 1], np.int64), np.ones(1)
    hold_rhs(np.zeros((2, 1, 3)), z3, z3, 0.01, i1[:1], i1, f1, f1, z3[:1], z3[:1],
             i1, np.array([0, 1, 2], np.int64), f1, f1, np.zeros((1, 1, 9)))
    tether_pull(z3, z3, i1[:1], i1, f1, f1, z3[:1], z3[:1])
    lowrank_update(np.zeros((2, 3)), np.zeros((2, 1)), np.ones((1, 1)), i1[:1], i1)
