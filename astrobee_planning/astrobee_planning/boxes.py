"""The robot's safe set as a union of axis-aligned boxes, its overlap graph and box routing.

The keep-in boxes of config/iss.yaml touch face to face, so shrinking each one by the robot's
radius on its own disconnects them at every hatch. Besides every shrunk keep-in box we add a
"passage" box for each touching/overlapping pair (astrobee.station.passage_boxes): it lies
inside the union of the two (so, shrunk by the radius, its points keep the robot's ball inside
the keep-in set) and overlaps both shrunk boxes, which reconnects the graph through the hatch.
Boxes are arrays [xmin, ymin, zmin, xmax, ymax, zmax]; their algebra is astrobee.station's.
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass, field

import numpy as np

from astrobee import config
from astrobee.station import drop_contained, extent, intersect, passage_boxes, robot_radius, shrink

from .errors import NoRoute, OutsideSafeSet

MIN_OVERLAP = 0.02   # m: two safe boxes are neighbours when their intersection is this thick
BOX_PENALTY = 1.0    # m added per box entered: fewer, longer segments (a smaller QP)


@dataclass
class SafeSet:
    """Union of boxes where the robot's centre may be, with their overlap graph."""
    boxes: np.ndarray                       # (N, 6)
    margin: np.ndarray                      # per-axis shrink applied to the keep-in set
    edges: dict[int, list[int]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.edges = {i: [] for i in range(len(self.boxes))}
        self._overlap: dict[tuple[int, int], np.ndarray] = {}
        for i in range(len(self.boxes)):
            for j in range(i + 1, len(self.boxes)):
                inter = intersect(self.boxes[i], self.boxes[j])
                if np.all(extent(inter) >= MIN_OVERLAP):
                    self.edges[i].append(j)
                    self.edges[j].append(i)
                    self._overlap[(i, j)] = self._overlap[(j, i)] = inter

    def overlap(self, i: int, j: int) -> np.ndarray:
        return self._overlap[(i, j)]

    def containing(self, p: np.ndarray, tol: float = 1e-9) -> list[int]:
        """Indices of the boxes holding point p."""
        p = np.asarray(p, dtype=float)
        b = self.boxes
        inside = np.all((p >= b[:, :3] - tol) & (p <= b[:, 3:] + tol), axis=1)
        return [int(i) for i in np.flatnonzero(inside)]

    def contains(self, p: np.ndarray, tol: float = 1e-9) -> bool:
        return bool(self.containing(p, tol))

    def contains_all(self, pts: np.ndarray, tol: float = 1e-9) -> np.ndarray:
        """Boolean per row of pts (M, 3): inside some box."""
        pts = np.atleast_2d(pts)
        b = self.boxes
        inside = np.all((pts[:, None, :] >= b[None, :, :3] - tol)
                        & (pts[:, None, :] <= b[None, :, 3:] + tol), axis=2)
        return inside.any(axis=1)

    def route(self, start: np.ndarray, goal: np.ndarray) -> list[int]:
        """Shortest box sequence from start to goal: Dijkstra over overlap regions, edge
        weights the distances between overlap centres (start and goal as end nodes)."""
        start = np.asarray(start, dtype=float)
        goal = np.asarray(goal, dtype=float)
        s_boxes, g_boxes = self.containing(start), self.containing(goal)
        if not s_boxes:
            raise OutsideSafeSet(f"start {start.round(3).tolist()} is outside the safe set")
        if not g_boxes:
            raise OutsideSafeSet(f"goal {goal.round(3).tolist()} is outside the safe set")
        common = set(s_boxes) & set(g_boxes)
        if common:
            return [min(common, key=lambda k: -np.min(extent(self.boxes[k])))]
        # state: (box we are in, point where we entered it); path of boxes kept
        centre = lambda i, j: 0.5 * (self.overlap(i, j)[:3] + self.overlap(i, j)[3:])  # noqa: E731
        best: dict[tuple[int, int], float] = {}
        heap: list[tuple[float, int, int, int, tuple[int, ...]]] = []
        count = 0
        for b in s_boxes:
            heapq.heappush(heap, (0.0, count, b, -1, (b,)))
            count += 1
        goal_set = set(g_boxes)
        while heap:
            cost, _, box, prev, path = heapq.heappop(heap)
            point = start if prev < 0 else centre(prev, box)
            if box in goal_set:
                return list(path)  # cost includes entry; goal leg compared below
            key = (box, prev)
            if best.get(key, np.inf) < cost:
                continue
            for nb in self.edges[box]:
                if nb in path:
                    continue
                c = centre(box, nb)
                new = cost + float(np.linalg.norm(c - point)) + BOX_PENALTY
                if nb in goal_set:
                    new += float(np.linalg.norm(goal - c))
                k = (nb, box)
                if new < best.get(k, np.inf):
                    best[k] = new
                    count += 1
                    heapq.heappush(heap, (new, count, nb, box, path + (nb,)))
        raise NoRoute(f"no chain of safe boxes joins {start.round(3).tolist()} "
                      f"and {goal.round(3).tolist()}")


def keep_in_boxes() -> np.ndarray:
    return config.keep_in_boxes()


def safe_set(carry_extent: float | np.ndarray = 0.0, radius: float | None = None,
             keep_in: np.ndarray | None = None) -> SafeSet:
    """Safe set for the robot centre: keep-in boxes plus passage boxes, shrunk by the robot's
    radius plus `carry_extent` (scalar or per-axis), boxes that vanish dropped."""
    r = robot_radius() if radius is None else float(radius)
    margin = r + np.broadcast_to(np.asarray(carry_extent, dtype=float), (3,))
    raw = keep_in_boxes() if keep_in is None else np.asarray(keep_in, dtype=float)
    allb = np.vstack([raw, passage_boxes(raw)])
    shr = shrink(allb, margin)
    shr = shr[np.all(extent(shr) > 0.0, axis=1)]
    return SafeSet(drop_contained(shr, tol=0.0), margin)   # boxes inside another add nothing
