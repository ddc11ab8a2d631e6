"""Station geometry shared by the planner, the controllers and the safety filter: the robot's
radius and the axis-aligned box algebra over the keep-in set.

The keep-in boxes of config/iss.yaml touch face to face at every hatch, so no single box holds a
robot crossing a hatch. Two kinds of box inside the union of keep-in boxes reconnect them:
a *passage* box per touching pair (`passage_boxes`) and the merged *chains* of boxes along one
axis (`merged_chains`), long enough to hold a long load through consecutive hatches.
Boxes are arrays [xmin, ymin, zmin, xmax, ymax, zmax] in the world frame.
"""
from __future__ import annotations

import numpy as np

from astrobee import config


def robot_radius() -> float:
    """Radius (m) of the sphere around the robot's envelope (the planner's collision sphere,
    ~ the 0.32 m cube's circumscribed sphere)."""
    return float(config.astrobee()["planner_radius"])


def grow(boxes: np.ndarray, margin: float | np.ndarray) -> np.ndarray:
    """Boxes grown by `margin` (scalar or per-axis 3-vector) on every face."""
    m = np.broadcast_to(np.asarray(margin, dtype=float), (3,))
    b = np.array(boxes, dtype=float, ndmin=2)
    return np.hstack([b[:, :3] - m, b[:, 3:] + m])


def shrink(boxes: np.ndarray, margin: float | np.ndarray) -> np.ndarray:
    """Boxes shrunk by `margin` (scalar or per-axis 3-vector) on every face."""
    m = np.broadcast_to(np.asarray(margin, dtype=float), (3,))
    b = np.array(boxes, dtype=float, ndmin=2)
    return np.hstack([b[:, :3] + m, b[:, 3:] - m])


def intersect(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The intersection of two boxes (negative extents where they do not meet)."""
    return np.concatenate([np.maximum(a[:3], b[:3]), np.minimum(a[3:], b[3:])])


def extent(box: np.ndarray) -> np.ndarray:
    """Size of one box per axis, or of each row of an (N, 6) array."""
    return box[..., 3:] - box[..., :3]


def contains(box: np.ndarray, p: np.ndarray, tol: float = 1e-9) -> bool:
    """Whether point p lies in the box (within tol)."""
    return bool(np.all(p >= box[:3] - tol) and np.all(p <= box[3:] + tol))


def passage_boxes(boxes: np.ndarray, touch_tol: float = 1e-6) -> np.ndarray:
    """Boxes inside the union of two touching/overlapping keep-in boxes, spanning both along
    each axis on which their cross-sections (the other two axes) overlap."""
    out = []
    n = len(boxes)
    for i in range(n):
        for j in range(i + 1, n):
            a, b = boxes[i], boxes[j]
            inter = intersect(a, b)
            ext = extent(inter)
            if np.any(ext < -touch_tol):
                continue
            for ax in range(3):
                others = [k for k in range(3) if k != ax]
                if np.any(ext[others] <= touch_tol):
                    continue
                box = inter.copy()
                box[ax] = min(a[ax], b[ax])
                box[ax + 3] = max(a[ax + 3], b[ax + 3])
                out.append(box)
    return np.array(out).reshape(-1, 6)


def merged_chains(boxes: np.ndarray, rounds: int, min_cross: float, touch_tol: float = 1e-6,
                  length_tol: float = 1e-6) -> np.ndarray:
    """Boxes made by merging chains of up to rounds+1 boxes along one axis: consecutive boxes
    must touch or overlap along that axis (within touch_tol) and share a cross-section at least
    `min_cross` m wide on both other axes; the result spans the chain along the axis and keeps
    the common cross-section, so every slice of it lies in one of the chain's boxes. A box that
    adds no more than `length_tol` along the axis ends the chain."""
    raw = np.asarray(boxes, float)
    out: list[np.ndarray] = []
    for ax in range(3):
        o_lo = np.array([k for k in range(3) if k != ax])
        o_hi = o_lo + 3
        frontier = list(raw)
        for _ in range(rounds):
            grown: list[np.ndarray] = []
            for t in frontier:
                touch = (raw[:, ax] <= t[ax + 3] + touch_tol) & (raw[:, ax + 3] >= t[ax] - touch_tol)
                for b in raw[touch]:
                    lo = np.maximum(t[o_lo], b[o_lo])
                    hi = np.minimum(t[o_hi], b[o_hi])
                    if np.any(hi - lo < min_cross):
                        continue
                    m = t.copy()
                    m[o_lo], m[o_hi] = lo, hi
                    m[ax], m[ax + 3] = min(t[ax], b[ax]), max(t[ax + 3], b[ax + 3])
                    if m[ax + 3] - m[ax] <= t[ax + 3] - t[ax] + length_tol:
                        continue          # b adds no length along the axis
                    if not any(np.allclose(m, g) for g in grown):
                        grown.append(m)
            out.extend(grown)
            frontier = grown
            if not grown:
                break
    return np.array(out).reshape(-1, 6)


def drop_contained(boxes: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """The boxes not contained (within tol) in another one (of equal boxes the first is kept)."""
    b = np.asarray(boxes, float)
    keep = np.ones(len(b), dtype=bool)
    for i in range(len(b)):
        inside = np.all(b[i, :3] >= b[:, :3] - tol, axis=1) & np.all(b[i, 3:] <= b[:, 3:] + tol, axis=1)
        inside[i] = False
        same = np.all(np.abs(b - b[i]) <= tol, axis=1)
        inside &= keep & ~(same & (np.arange(len(b)) > i))
        if inside.any():
            keep[i] = False
    return b[keep]
