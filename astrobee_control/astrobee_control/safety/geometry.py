"""Geometry of the safety filter: the boxes the robot's envelope must stay in, and the envelope.

The keep-in boxes of config/iss.yaml touch face to face at every hatch, so no single keep-in box
holds a robot crossing a hatch. The filter therefore chooses, per envelope point, one box out of
a set of *corridor boxes*: the keep-in boxes (grown by the filter's margin) plus every chain of
them merged along one axis (the chain's span along that axis times the intersection of their
cross-sections). Each merged box lies inside the union of its chain, so keeping a point inside
any one candidate box keeps it inside the union; a long corridor (Node 2 -> hatch -> JEM) is one
box, which is what lets the filter stay transparent while the robot flies through a hatch.

Boxes are arrays [xmin, ymin, zmin, xmax, ymax, zmax] in the world frame.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from astrobee import config


@dataclass(frozen=True)
class BodySphere:
    """A sphere fixed to the robot: centre at `offset` (m, BODY frame, from the robot point) and
    `radius` (m; 0 for a point such as a box corner)."""

    offset: np.ndarray
    radius: float


def robot_radius() -> float:
    """Radius of the sphere around the robot's envelope (the planner's, ~ the 0.32 m cube's
    circumscribed sphere)."""
    return float(config.astrobee()["planner_radius"])


def robot_sphere(radius: float | None = None) -> BodySphere:
    return BodySphere(np.zeros(3), robot_radius() if radius is None else float(radius))


def box_corners(centre_offset: np.ndarray, size: np.ndarray,
                rotation_body: np.ndarray | None = None) -> list[BodySphere]:
    """The 8 corners of a carried box (e.g. a cargo bag) as zero-radius body points: a box lies
    in a convex box exactly when its corners do. `rotation_body` (3x3) turns the box's own axes
    into the robot body frame."""
    c = np.asarray(centre_offset, float)
    half = 0.5 * np.asarray(size, float)
    r = np.eye(3) if rotation_body is None else np.asarray(rotation_body, float)
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    return [BodySphere(c + r @ (s * half), 0.0) for s in signs]


def box_sphere(centre_offset: np.ndarray, size: np.ndarray) -> BodySphere:
    """A carried box as its circumscribed sphere (one point instead of eight; conservative)."""
    return BodySphere(np.asarray(centre_offset, float),
                      float(0.5 * np.linalg.norm(np.asarray(size, float))))


def grow(boxes: np.ndarray, margin: float) -> np.ndarray:
    b = np.array(boxes, dtype=float, ndmin=2)
    return np.hstack([b[:, :3] - margin, b[:, 3:] + margin])


def merged_chains(boxes: np.ndarray, rounds: int = 4, min_cross: float = 0.3,
                  tol: float = 1e-6) -> np.ndarray:
    """Boxes made by merging chains of up to rounds+1 boxes along one axis: consecutive boxes
    must touch or overlap along that axis and share a cross-section at least `min_cross` m
    wide on both other axes; the result spans the chain along the axis and keeps the common
    cross-section, so every slice of it lies in one of the chain's boxes."""
    raw = np.asarray(boxes, float)
    out: list[np.ndarray] = []
    for ax in range(3):
        o_lo = np.array([k for k in range(3) if k != ax])
        o_hi = o_lo + 3
        frontier = list(raw)
        for _ in range(rounds):
            grown: list[np.ndarray] = []
            for t in frontier:
                touch = (raw[:, ax] <= t[ax + 3] + tol) & (raw[:, ax + 3] >= t[ax] - tol)
                for b in raw[touch]:
                    lo = np.maximum(t[o_lo], b[o_lo])
                    hi = np.minimum(t[o_hi], b[o_hi])
                    if np.any(hi - lo < min_cross):
                        continue
                    m = t.copy()
                    m[o_lo], m[o_hi] = lo, hi
                    m[ax], m[ax + 3] = min(t[ax], b[ax]), max(t[ax + 3], b[ax + 3])
                    if m[ax + 3] - m[ax] <= t[ax + 3] - t[ax] + tol:
                        continue          # b adds no length along the axis
                    if not any(np.allclose(m, g) for g in grown):
                        grown.append(m)
            out.extend(grown)
            frontier = grown
            if not grown:
                break
    return np.array(out).reshape(-1, 6)


def drop_contained(boxes: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """The boxes not contained in another one (of equal boxes the first is kept)."""
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


def corridor_boxes(keep_in: np.ndarray | None = None, margin: float = 0.0) -> np.ndarray:
    """Candidate boxes for the filter: keep-in boxes grown by `margin` plus their merged chains,
    boxes inside another dropped. Default: the station's keep-in set (cached)."""
    if keep_in is None:
        return _station_corridors(float(margin)).copy()
    g = grow(keep_in, margin)
    return drop_contained(np.vstack([g, merged_chains(g)]))


@lru_cache(maxsize=8)
def _station_corridors(margin: float) -> np.ndarray:
    g = grow(config.keep_in_boxes(), margin)
    return drop_contained(np.vstack([g, merged_chains(g)]))
