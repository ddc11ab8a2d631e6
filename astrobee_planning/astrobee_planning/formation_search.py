"""Where a two-robot formation may go: its 24 axis-aligned orientations, the safe centre sets
of each, the sweep check of its turns, and the Dijkstra search over (orientation, box).

multi_robot.py turns the searched path into a timed plan; see its docstring for the plan shape.
"""
from __future__ import annotations

import heapq
import itertools
from functools import lru_cache

import numpy as np

from astrobee import config, station
from astrobee import rotations as rot

from . import boxes as bx
from . import planner
from .errors import NoRoute, OutsideSafeSet
from .quaternion_poly import QuaternionPolynomial, reorientation

MIN_OVERLAP = 0.02       # m: boxes joined by a move or a turn overlap at least this much
BOX_COST = 0.5           # s added per box entered (fewer, longer legs)
TURN_CHECK_STEPS = 40    # samples of a turn's sweep in the search


def _rotations() -> np.ndarray:
    """The 24 proper signed permutation matrices (axis-aligned orientations)."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            m[range(3), perm] = signs
            if np.linalg.det(m) > 0:
                out.append(m)
    return np.array(out)


ROTS = _rotations()
ROT_QUATS = np.array([rot.from_matrix(m) for m in ROTS])


def _hatch_labels() -> list[tuple[str, np.ndarray]]:
    return [(k["module"], np.array(k["box"], float)) for k in config.iss()["keep_in"] if "/" in k["module"]]


@lru_cache(maxsize=None)
def keep_in_region() -> np.ndarray:
    """Boxes whose union is the keep-in set: keep-in, passage and tube boxes."""
    raw = config.keep_in_boxes()
    tubes = station.merged_chains(raw, rounds=3, min_cross=0.1, length_tol=1e-9)
    return station.drop_contained(np.vstack([raw, station.passage_boxes(raw), tubes]), tol=1e-12)


@lru_cache(maxsize=None)
def robot_set(radius: float) -> bx.SafeSet:
    """Safe centres of one robot sphere: the keep-in region shrunk by its radius."""
    return _shrunk(tuple(np.full(3, radius)))


@lru_cache(maxsize=64)
def _shrunk(margin: tuple) -> bx.SafeSet:
    s = station.shrink(keep_in_region(), np.array(margin))
    s = s[np.all(station.extent(s) > 0.0, axis=1)]
    return bx.SafeSet(station.drop_contained(s, tol=1e-12), np.array(margin))


def in_region(pts: np.ndarray) -> np.ndarray:
    """Which points lie in the keep-in region (any of its boxes)."""
    b = keep_in_region()
    return np.any(np.all((pts[:, None, :] >= b[None, :, :3] - 1e-9)
                         & (pts[:, None, :] <= b[None, :, 3:] + 1e-9), axis=2), axis=1)


class Formation:
    """Geometry of the formation in the bag frame and its safe centre sets per orientation."""

    def __init__(self, offset: np.ndarray, bag_half: np.ndarray, radius: float):
        self.offset, self.bag_half, self.radius = offset, bag_half, radius
        self.lever = float(np.linalg.norm(offset))
        g = np.linspace(-1.0, 1.0, 5)
        grid = np.array(list(itertools.product(g, g, g)))
        self.bag_pts = grid[np.any(np.abs(grid) == 1.0, axis=1)] * bag_half   # surface grid
        self.margins = np.array([self.margin(m) for m in ROTS])
        keys = [tuple(np.round(m, 9)) for m in self.margins]
        self.cls = [sorted(set(keys)).index(k) for k in keys]
        self.sets = [_shrunk(k) for k in sorted(set(keys))]

    def margin(self, r: np.ndarray) -> np.ndarray:
        robots = np.abs(r @ self.offset) + self.radius
        return np.maximum(robots, np.abs(r) @ self.bag_half)

    def safe_poses(self, p: np.ndarray, q: np.ndarray) -> str | None:
        """None when robots (spheres) and bag (surface points) at centres p (M,3), bag
        orientations q (M,4) are in the keep-in set, else what is not."""
        rs = robot_set(self.radius)
        for sign, name in ((1.0, "robot 0"), (-1.0, "robot 1")):
            rp = p + rot.rotate(q, np.broadcast_to(sign * self.offset, p.shape))
            bad = ~rs.contains_all(rp)
            if bad.any():
                return f"{name} leaves the safe set at {np.round(rp[bad][0], 3).tolist()}"
        # a bag whose 8 corners lie in one (convex) region box is inside it; only the other
        # poses have their surface points checked against the union
        corners = np.array(list(itertools.product((-1.0, 1.0), repeat=3))) * self.bag_half
        cp = p[:, None, :] + np.einsum("mij,kj->mki", rot.to_matrix(q), corners)     # (M, 8, 3)
        lo, hi = cp.min(axis=1), cp.max(axis=1)                                     # (M, 3)
        b = keep_in_region()
        one = np.zeros(len(p), dtype=bool)
        for box in b:
            one |= np.all(lo >= box[:3] - 1e-9, axis=1) & np.all(hi <= box[3:] + 1e-9, axis=1)
        rest = np.flatnonzero(~one)
        if len(rest):
            pr, qr = p[rest], q[rest]
            m, k = len(pr), len(self.bag_pts)
            bp = np.repeat(pr, k, axis=0) + rot.rotate(np.repeat(qr, k, axis=0), np.tile(self.bag_pts, (m, 1)))
            bad = ~in_region(bp)
            if bad.any():
                return f"the bag leaves the keep-in set at {np.round(bp[bad][0], 3).tolist()}"
        return None

    def turn_ok(self, p: np.ndarray, qa: np.ndarray, qb: np.ndarray) -> bool:
        qs = np.array([rot.slerp(qa, qb, s) for s in np.linspace(0.0, 1.0, TURN_CHECK_STEPS)])
        return self.safe_poses(np.tile(p, (len(qs), 1)), qs) is None


class Limits:
    """The formation's limits: the mode's, the turn rate capped so the robots at the lever keep v."""

    def __init__(self, mode, lever: float):
        self.v, self.a = mode.hard_limit_vel, mode.hard_limit_accel
        self.w = min(mode.hard_limit_omega, 0.98 * self.v / lever) if lever > 0 else mode.hard_limit_omega
        self.al = mode.hard_limit_alpha
        self.lever = lever

    def turn_time(self, theta: float) -> float:
        """Rest-to-rest quintic: peak w 1.875 th/T, peak alpha 5.774 th/T^2; robots' linear
        acceleration bounded by d (alpha + w^2)."""
        if theta < 1e-9:
            return 0.0
        t = max(1.875 * theta / self.w, np.sqrt(5.7735 * theta / self.al))
        if self.lever > 0:
            t = max(t, np.sqrt(self.lever * theta * (5.7735 + 3.5157 * theta) / (0.97 * self.a)))
        return float(t)

    def turn(self, qa, qb, t0: float) -> QuaternionPolynomial:
        theta = rot.angle_between(qa, qb)
        return reorientation(qa, qb, self.w, self.al, t0=t0, min_duration=self.turn_time(theta))


def angle(qa, qb) -> float:
    return float(rot.angle_between(qa, qb))


ROT_ANGLES = np.array([[angle(a, b) for b in ROT_QUATS] for a in ROT_QUATS])


def search(form: Formation, lim: Limits, p0, q0, p1, q1, forbidden: set):
    """Dijkstra over (orientation index, box index) nodes; returns the node path with points and
    entry kinds, or None."""
    restart = lim.v / lim.a          # a stop and restart costs about v/a seconds
    heap: list = []
    count = itertools.count()
    start_rot = [i for i in range(24) if angle(q0, ROT_QUATS[i]) < 1e-6]
    for i in range(24):
        s = form.sets[form.cls[i]]
        th = angle(q0, ROT_QUATS[i])
        if i not in start_rot and (("start", i) in forbidden or th > 2.1):
            continue
        cost = 0.0 if i in start_rot else lim.turn_time(th)
        for b in s.containing(p0):
            heapq.heappush(heap, (cost, next(count), (i, b), p0, None, "start"))
    done: dict = {}
    goal_rot = [i for i in range(24) if angle(q1, ROT_QUATS[i]) < 1e-6]
    while heap:
        cost, _, node, pt, prev, kind = heapq.heappop(heap)
        if node == "goal":
            path = [("goal", p1, kind)]
            cur = prev
            while cur is not None:
                n, ptn, pv, kd = done[cur]
                path.append((cur, ptn, kd))
                cur = pv
            return path[::-1]
        if node in done:
            continue
        done[node] = (node, pt, prev, kind)
        i, b = node
        s = form.sets[form.cls[i]]
        box = s.boxes[b]
        if station.contains(box, p1):
            th = angle(ROT_QUATS[i], q1)
            if i in goal_rot or (("goal", i) not in forbidden and th <= 2.1):
                extra = 0.0 if i in goal_rot else lim.turn_time(th) + restart
                heapq.heappush(heap, (cost + np.linalg.norm(p1 - pt) / lim.v + extra,
                                      next(count), "goal", p1, node, "end"))
        for nb in s.edges[b]:
            if (i, nb) in done:
                continue
            c = s.overlap(b, nb)
            c = 0.5 * (c[:3] + c[3:])
            heapq.heappush(heap, (cost + np.linalg.norm(c - pt) / lim.v + BOX_COST, next(count),
                                  (i, nb), c, node, "move"))
        for j in range(24):
            if j == i or ROT_ANGLES[i, j] > np.pi / 2 + 1e-6:
                continue
            sj = form.sets[form.cls[j]]
            lo = np.maximum(box[:3], sj.boxes[:, :3])
            hi = np.minimum(box[3:], sj.boxes[:, 3:])
            ok = np.all(hi - lo >= MIN_OVERLAP, axis=1)
            for nb in np.flatnonzero(ok):
                nb = int(nb)
                if (j, nb) in done or ((i, b), (j, nb)) in forbidden:
                    continue
                c = 0.5 * (lo[nb] + hi[nb])
                t = np.linalg.norm(c - pt) / lim.v + lim.turn_time(ROT_ANGLES[i, j]) + restart
                heapq.heappush(heap, (cost + t + BOX_COST, next(count), (j, nb), c, node, "turn"))
    return None


def narrow_hatch(form: Formation, p0, p1) -> str:
    """Which hatch on the robot's own route is narrower than the formation's cross-section."""
    rs = planner.cached_safe_set(0.0)
    try:
        route = rs.boxes[rs.route(p0, p1)]
    except (NoRoute, OutsideSafeSet):
        return "no route joins start and goal even for one robot"
    best_cross = {}
    for name, h in _hatch_labels():
        on_route = any(np.all(station.extent(station.intersect(h, r)) > 0) for r in route)
        if not on_route:
            continue
        e = station.extent(h)
        fits = False
        for ax in range(3):      # the formation passes along ax
            oth = [k for k in range(3) if k != ax]
            for m in form.margins:
                if np.all(2 * m[oth] <= e[oth]):
                    fits = True
            if fits:
                break
        if not fits:
            ax = int(np.argmin(e))   # a hatch box is thinnest along the direction it is crossed
            oth = [k for k in range(3) if k != ax]
            cross = min((2 * m[oth] for m in form.margins), key=lambda c: float(np.prod(c)))
            best_cross[name] = (e[oth], cross)
    if not best_cross:
        return "no sequence of moves and in-place turns keeps both robots and the bag inside"
    name, (e, c) = next(iter(best_cross.items()))
    return (f"hatch {name} is {e[0]:.2f} x {e[1]:.2f} m across, narrower than the formation's "
            f"smallest cross-section {c[0]:.2f} x {c[1]:.2f} m (robot diameter "
            f"{2 * form.radius:.3f} m, bag {np.round(2 * form.bag_half, 3).tolist()} m)")


def first_bad_turn(form, path, q0, q1):
    """The forbidden-set key of the first turn of the path whose sweep is unsafe, else None."""
    (i0, _), pt0, _ = path[0]
    if angle(q0, ROT_QUATS[i0]) > 1e-6 and not form.turn_ok(pt0, q0, ROT_QUATS[i0]):
        return ("start", i0)
    for (prev, _, _), (node, pt, kind) in zip(path[:-1], path[1:]):
        if kind == "turn":
            if not form.turn_ok(pt, ROT_QUATS[prev[0]], ROT_QUATS[node[0]]):
                return (prev, node)
    last = path[-2][0][0]
    if angle(ROT_QUATS[last], q1) > 1e-6 and not form.turn_ok(path[-1][1], ROT_QUATS[last], q1):
        return ("goal", last)
    return None
