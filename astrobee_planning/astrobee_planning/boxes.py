"""The robot's safe set as a union of axis-aligned boxes, its overlap graph and box routing.

The keep-in boxes of config/iss.yaml touch face to face, so shrinking each one by the robot's
radius on its own disconnects them at every hatch. Besides every shrunk keep-in box we add a
"passage" box for each touching/overlapping pair: the span of both boxes along the axis they
meet on, times the intersection of their cross-sections. That box lies inside the union of the
two (so, shrunk by the radius, its points keep the robot's ball inside the keep-in set) and
overlaps both shrunk boxes, which reconnects the graph through the hatch.
Boxes are arrays [xmin, ymin, zmin, xmax, ymax, zmax].
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass, field

import numpy as np

from astrobee import config

from .errors import NoRoute, OutsideSafeSet

MIN_OVERLAP = 0.02   # m: two safe boxes are neighbours when their intersection is this thick
BOX_PENALTY = 1.0    # m added per box entered: fewer, longer segments (a smaller QP)


def robot_radius() -> float:
    return float(config.astrobee()["planner_radius"])


def shrink(boxes: np.ndarray, margin: float | np.ndarray) -> np.ndarray:
    """Shrink boxes by `margin` (scalar or per-axis 3-vector) on every face."""
    m = np.broadcast_to(np.asarray(margin, dtype=float), (3,))
    b = np.array(boxes, dtype=float, ndmin=2)
    return np.hstack([b[:, :3] + m, b[:, 3:] - m])


def intersect(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.concatenate([np.maximum(a[:3], b[:3]), np.minimum(a[3:], b[3:])])


def extent(box: np.ndarray) -> np.ndarray:
    return box[3:] - box[:3]


def contains(box: np.ndarray, p: np.ndarray, tol: float = 1e-9) -> bool:
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
    keep = np.all(extent_rows(shr) > 0.0, axis=1)
    shr = shr[keep]
    # drop boxes contained in another one (they add nothing)
    keep = np.ones(len(shr), dtype=bool)
    for i in range(len(shr)):
        for j in range(len(shr)):
            if i != j and keep[j] and np.all(shr[i, :3] >= shr[j, :3]) and np.all(shr[i, 3:] <= shr[j, 3:]):
                if not (np.allclose(shr[i], shr[j]) and i < j):
                    keep[i] = False
                    break
    return SafeSet(shr[keep], margin)


def extent_rows(b: np.ndarray) -> np.ndarray:
    return b[:, 3:] - b[:, :3]


def tube_boxes(boxes: np.ndarray, rounds: int = 3, min_cross: float = 0.1,
               touch_tol: float = 1e-6) -> np.ndarray:
    """Chains of up to `rounds`+1 keep-in boxes merged along one axis: the span of the chain
    along that axis times the intersection of their cross-sections (at least `min_cross` m
    across). Each lies inside the union of its chain, and unlike pairwise passage boxes it stays
    long enough to hold an elongated load through two consecutive hatch boxes."""
    raw = np.asarray(boxes, dtype=float)
    out = []
    for ax in range(3):
        oth = [k for k in range(3) if k != ax]
        lo_o, hi_o = np.array(oth), np.array(oth) + 3
        cur = list(raw)
        for _ in range(rounds):
            new = []
            for t in cur:
                for b in raw:
                    if b[ax] > t[ax + 3] + touch_tol or b[ax + 3] < t[ax] - touch_tol:
                        continue
                    clo, chi = np.maximum(t[lo_o], b[lo_o]), np.minimum(t[hi_o], b[hi_o])
                    if np.any(chi - clo < min_cross):
                        continue
                    m = t.copy()
                    m[lo_o], m[hi_o] = clo, chi
                    m[ax], m[ax + 3] = min(t[ax], b[ax]), max(t[ax + 3], b[ax + 3])
                    if m[ax + 3] - m[ax] <= t[ax + 3] - t[ax] + 1e-9:
                        continue
                    if not any(np.allclose(m, o) for o in new):
                        new.append(m)
            out.extend(new)
            cur = new
            if not new:
                break
    return np.array(out).reshape(-1, 6)


def drop_contained(b: np.ndarray) -> np.ndarray:
    """Boxes not contained in another (of two equal boxes the first is kept)."""
    keep = np.ones(len(b), dtype=bool)
    for i in range(len(b)):
        inside = np.all(b[i, :3] >= b[:, :3] - 1e-12, axis=1) & np.all(b[i, 3:] <= b[:, 3:] + 1e-12, axis=1)
        inside[i] = False
        same = np.all(np.abs(b - b[i]) < 1e-12, axis=1)
        inside &= keep & ~(same & (np.arange(len(b)) > i))
        if inside.any():
            keep[i] = False
    return b[keep]
