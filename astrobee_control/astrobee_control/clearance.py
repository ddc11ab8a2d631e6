"""Signed clearance of points to the keep-in box union, vectorised for the MPC's cost.

Positive inside the union (distance to its boundary, lower bound), negative outside (distance
to the nearest box). For one box the signed distance is exact; for the union the maximum over
boxes is a lower bound inside it, too pessimistic only where two boxes meet face to face (a
point on a hatch plane would read 0). So the union is augmented with each touching pair's
passage box (astrobee.station.passage_boxes, which the planner's safe set uses too),
which restores the true clearance through every hatch.

`KeepIn.clearance` first drops the boxes farther than `reach` from the points' bounding box:
a few of the ~50 boxes matter for one horizon, and the cost falls accordingly.
"""
from __future__ import annotations

import numpy as np

from astrobee.station import passage_boxes

# the 8 corners of a unit box about its centre (x half-size per axis: a box's corners, whose
# clearance bounds the box's)
CUBE = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)


def box_corners(centre: np.ndarray, rotation: np.ndarray, size: np.ndarray) -> np.ndarray:
    """The 8 corners (8 x 3) of a box of `size` at `centre`, its axes turned by `rotation`."""
    return np.asarray(centre, float) + (CUBE * (0.5 * np.asarray(size, float))) @ \
        np.asarray(rotation, float).T


class KeepIn:
    """The keep-in union (keep-in boxes + passage boxes) as signed-distance queries."""

    def __init__(self, boxes: np.ndarray) -> None:
        boxes = np.asarray(boxes, float).reshape(-1, 6)
        self.boxes = np.vstack([boxes, passage_boxes(boxes)])

    def near(self, lo: np.ndarray, hi: np.ndarray, reach: float) -> np.ndarray:
        """Boxes within `reach` of the axis-aligned region [lo, hi]."""
        b = self.boxes
        keep = np.all((b[:, :3] <= hi + reach) & (b[:, 3:] >= lo - reach), axis=1)
        return b[keep]

    def clearance(self, points: np.ndarray, reach: float = 0.5) -> np.ndarray:
        """Signed clearance (m) of points (..., 3); boxes beyond `reach` of them ignored
        (a point farther than `reach` outside every box reads -reach or less)."""
        pts = np.asarray(points, float)
        flat = pts.reshape(-1, 3)
        if flat.size == 0:
            return np.zeros(pts.shape[:-1])
        boxes = self.near(flat.min(axis=0), flat.max(axis=0), reach)
        best = np.full(len(flat), -float(reach))
        x, y, z = (np.ascontiguousarray(flat[:, k]) for k in range(3))
        for b in boxes:   # a handful of boxes; each pass is vectorised over all points
            # per axis: > 0 outside the slab by that much, < 0 inside by that much
            dx = np.maximum(b[0] - x, x - b[3])
            dy = np.maximum(b[1] - y, y - b[4])
            dz = np.maximum(b[2] - z, z - b[5])
            worst = np.maximum(np.maximum(dx, dy), dz)
            out = np.sqrt(np.maximum(dx, 0.0) ** 2 + np.maximum(dy, 0.0) ** 2
                          + np.maximum(dz, 0.0) ** 2)
            np.maximum(best, np.where(worst < 0, -worst, -out), out=best)
        return best.reshape(pts.shape[:-1])
