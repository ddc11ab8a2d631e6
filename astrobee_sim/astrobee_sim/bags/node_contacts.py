"""Contact of mesh nodes with boxes: the station's wall slabs (static) and robot bodies (moving).

A node found inside a box (grown by a contact margin) after a step is put back on the face it
came through (the face its previous position was outside of; the shallowest face otherwise), its
velocity relative to the box loses the inward normal part (inelastic) and its tangential part
is cut by Coulomb friction with the normal impulse. Each node moves a few millimetres a step
and the walls are 0.25 m thick, so no node can cross a wall in one step. Pure numpy.
"""
from __future__ import annotations

import numpy as np

try:
    from numba import njit
except ImportError:          # numba missing: numpy's broad phase
    njit = None


def _near_boxes_loop(x, grown):  # pragma: no cover - compiled
    """Indices of the grown boxes overlapping the bounding box of points x (M, 3)."""
    lo0, lo1, lo2 = x[0, 0], x[0, 1], x[0, 2]
    hi0, hi1, hi2 = lo0, lo1, lo2
    for i in range(1, x.shape[0]):
        lo0, hi0 = min(lo0, x[i, 0]), max(hi0, x[i, 0])
        lo1, hi1 = min(lo1, x[i, 1]), max(hi1, x[i, 1])
        lo2, hi2 = min(lo2, x[i, 2]), max(hi2, x[i, 2])
    out = np.empty(grown.shape[0], np.int64)
    m = 0
    for b in range(grown.shape[0]):
        if (grown[b, 0] < hi0 and grown[b, 3] > lo0 and grown[b, 1] < hi1 and grown[b, 4] > lo1
                and grown[b, 2] < hi2 and grown[b, 5] > lo2):
            out[m] = b
            m += 1
    return out[:m]


_near_boxes = njit(cache=True)(_near_boxes_loop) if njit is not None else None


def push_out(q: np.ndarray, q_prev: np.ndarray, lo: np.ndarray, hi: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """For points q (M, 3) inside the box lo..hi: (axis, face) of the face each one leaves by;
    face 0 = the low face, 1 = the high face."""
    depth = np.concatenate([q - lo, hi - q], axis=1)                       # (M, 6)
    came = np.concatenate([q_prev < lo, q_prev > hi], axis=1)
    cand = np.where(came.any(axis=1, keepdims=True), np.where(came, depth, np.inf), depth)
    f = cand.argmin(axis=1)
    return f % 3, f // 3


def _respond(v: np.ndarray, u: np.ndarray, n: np.ndarray, mu: float) -> np.ndarray:
    """New velocities of nodes v (M, 3) touching a surface moving at u with outward normal n."""
    rel = v - u
    vn = np.einsum("ij,ij->i", rel, n)
    j = np.maximum(-vn, 0.0)                       # normal velocity removed (per unit mass)
    rel = rel + j[:, None] * n
    if mu > 0:
        t = rel - np.einsum("ij,ij->i", rel, n)[:, None] * n
        tn = np.sqrt(np.einsum("ij,ij->i", t, t))
        scale = np.where(tn > 0, np.maximum(0.0, 1.0 - mu * j / np.maximum(tn, 1e-300)), 1.0)
        rel = rel - (1.0 - scale)[:, None] * t
    return u + rel


def grow_boxes(boxes: np.ndarray, margin: float) -> np.ndarray:
    """Static boxes (B, 6 as lo, hi) grown by the contact margin, for collide_static_boxes."""
    b = np.asarray(boxes, dtype=float)
    return np.ascontiguousarray(np.concatenate([b[:, :3] - margin, b[:, 3:] + margin], axis=1))


def collide_static_boxes(x: np.ndarray, v: np.ndarray, x_prev: np.ndarray, boxes: np.ndarray,
                         margin: float, mu: float, grown: np.ndarray | None = None) -> float:
    """Keep points x (M, 3) out of static boxes (B, 6 as lo, hi), in place; returns the deepest
    penetration found before the correction (m, 0 when none). grown: grow_boxes(boxes, margin)
    when the caller keeps it (saves recomputing it every step)."""
    g = grow_boxes(boxes, margin) if grown is None else grown
    deepest = 0.0
    if _near_boxes is not None and len(x):
        cand = g[_near_boxes(x, g)]
    else:
        lo_all, hi_all = x.min(axis=0), x.max(axis=0)
        cand = g[((g[:, :3] < hi_all) & (g[:, 3:] > lo_all)).all(axis=1)]
    if not len(cand):
        return deepest
    # which near boxes hold a node at all, in one pass (usually none: the bag in open space)
    hit = ((x[None] > cand[:, None, :3]) & (x[None] < cand[:, None, 3:])).all(axis=2)
    moved = False           # once a box has moved nodes, later boxes are checked afresh
    for b, mask in zip(cand, hit):
        if not moved and not mask.any():
            continue
        lo, hi = b[:3], b[3:]
        inside = np.flatnonzero(np.all((x > lo) & (x < hi), axis=1))
        if not inside.size:
            continue
        moved = True
        q = x[inside]
        ax, face = push_out(q, x_prev[inside], lo, hi)
        rows = np.arange(len(inside))
        target = np.where(face == 0, lo[ax], hi[ax])
        deepest = max(deepest, float(np.abs(q[rows, ax] - target).max()))
        q[rows, ax] = target
        x[inside] = q
        n = np.zeros_like(q)
        n[rows, ax] = np.where(face == 0, -1.0, 1.0)
        v[inside] = _respond(v[inside], 0.0, n, mu)
    return deepest


def collide_moving_boxes(x: np.ndarray, v: np.ndarray, x_prev: np.ndarray, centre: np.ndarray,
                         rot: np.ndarray, vel: np.ndarray, omega: np.ndarray, half: np.ndarray,
                         margin: float, mu: float, node_mass: float, h: float,
                         skip: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Keep nodes x (N, K, 3) out of one oriented box per copy (centre (K, 3), rotation (K, 3, 3)
    box -> world, moving rigidly with vel, omega about the centre), in place.

    Returns the reaction on each box over the coming step: force (K, 3) and torque about the
    centre (K, 3), equal and opposite to the momentum the nodes gained. skip: node indices that
    never collide (the grasped handle)."""
    k = x.shape[1]
    force, torque = np.zeros((k, 3)), np.zeros((k, 3))
    lo, hi = -half - margin, half + margin
    # cheap reject: every node farther from the box centre than its circumscribed sphere
    r2 = float(np.dot(hi, hi))
    rel = x - centre[None]
    close = np.einsum("nkc,nkc->nk", rel, rel) < r2
    if skip is not None and len(skip):
        close[skip] = False
    if not close.any():
        return force, torque
    ni, ki = np.nonzero(close)
    R = rot[ki]                                                    # (M, 3, 3)
    q = np.einsum("mji,mj->mi", R, rel[ni, ki])
    inside = np.all((q > lo) & (q < hi), axis=1)
    if not inside.any():
        return force, torque
    ni, ki, R, q = ni[inside], ki[inside], R[inside], q[inside]
    qp = np.einsum("mji,mj->mi", R, x_prev[ni, ki] - centre[ki])
    ax, face = push_out(q, qp, lo, hi)
    rows = np.arange(len(ni))
    q[rows, ax] = np.where(face == 0, lo[ax], hi[ax])
    pos = centre[ki] + np.einsum("mij,mj->mi", R, q)
    x[ni, ki] = pos
    n = R[rows, :, ax] * np.where(face == 0, -1.0, 1.0)[:, None]
    arm = pos - centre[ki]
    u = vel[ki] + np.cross(omega[ki], arm)
    v_old = v[ni, ki]
    v_new = _respond(v_old, u, n, mu)
    v[ni, ki] = v_new
    f = -(node_mass / h) * (v_new - v_old)
    np.add.at(force, ki, f)
    np.add.at(torque, ki, np.cross(arm, f))
    return force, torque
