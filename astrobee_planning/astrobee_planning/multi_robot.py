"""Two robots carrying one two-handle bag as a rigid formation: robots at +offset and -offset
(bag frame) from the bag centre, the bag a box of half-extents `bag_half` around the centre.

Plan shape: the formation moves with its bag frame on one of the 24 axis-aligned orientations
(the robots in a line along a corridor, front/back handle, so a hatch only has to pass one robot
and the bag's cross-section) and turns in place, at rest, where a module has room. For an
axis-aligned orientation R the set of safe centres contains every keep-in box (plus passage and
tube boxes, see boxes.py) shrunk per axis by the formation's half-extent |R offset| + r (robot
spheres) and |R| bag_half (bag box); a translation leg is a time-optimal min-jerk spline
(global_planner) whose control points lie in those boxes, so both robots and the bag stay in
the keep-in set by construction, and with the orientation fixed each robot's velocity and
acceleration are the centre's. Turns are rest-to-rest quintic quaternion polynomials slowed so
that |alpha| d + |w|^2 d <= a_max and |w| d <= v_max for the lever arm d = |offset|. A turn
is first tried overlapping the braking of the leg before it and the speeding up of the leg
after it (no time held still for turning; the legs stay rest to rest at the turning point),
the whole plan then slowed uniformly until the robots' shared limits hold; the shortest plan
that passes the sampled check is kept, the stop-and-turn plan being the fallback. During such
an overlap only the sampled check (not the construction) keeps robots and bag inside.
The leg/turn sequence is a Dijkstra search over (orientation, box) with time costs; each turn is
checked by sampling its swept robots and bag, failing turns are forbidden and the search
repeated. The assembled plan is checked again by dense sampling (robot spheres, bag box
points, every limit) before it is returned. When no sequence exists the error names the hatch
narrower than the formation's cross-section.
"""
from __future__ import annotations

import heapq
import itertools
import time
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from astrobee import config, flight_modes
from astrobee import rotations as rot

from . import boxes as bx
from . import planner
from .global_planner import PlanningError, plan_position
from .planner import INVALID_COMMAND, PLAN_FAILED, VIOLATES_KEEP_IN, GlobalPlan, PlanError
from .quaternion_poly import QuaternionPolynomial, reorientation
from .trajectory import BezierPiece, State, Trajectory, check_sample_count

MIN_OVERLAP = 0.02       # m: boxes joined by a move or a turn overlap at least this much
BOX_COST = 0.5           # s added per box entered (fewer, longer legs)
TURN_CHECK_STEPS = 40    # samples of a turn's sweep in the search
MAX_SEARCHES = 40
# (overlap, stretch) tried in order: a turn overlaps the neighbouring legs by up to `overlap`
# of its duration on each side, slowed by `stretch`; (0, 1) is the stop-and-turn plan; the
# shortest plan that passes the check is kept
TURN_OVERLAPS = ((0.5, 1.0), (0.5, 1.3), (0.3, 1.3), (0.0, 1.0))


@dataclass
class OffsetTrajectory:
    """A robot rigidly attached at body-frame `offset` to a reference trajectory."""
    base: Trajectory
    offset: np.ndarray

    @property
    def duration(self) -> float:
        return self.base.duration

    def sample(self, t) -> State:
        st = self.base.sample(t)
        r = rot.rotate(st.quat, np.broadcast_to(self.offset, st.pos.shape))
        w, al = st.omega, st.alpha
        vel = st.vel + np.cross(w, r)
        acc = st.acc + np.cross(al, r) + np.cross(w, np.cross(w, r))
        return State(st.t, st.pos + r, vel, acc, st.quat, w, al)


@dataclass
class FormationPlan:
    centre: GlobalPlan                 # the bag centre (position + bag orientation)
    robots: list[OffsetTrajectory]     # at +offset and -offset
    bag_half: np.ndarray
    steps: list[str] = field(default_factory=list)   # "move ..." / "turn ..." in order


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
def _keep_in_region() -> np.ndarray:
    """Boxes whose union is the keep-in set: keep-in, passage and tube boxes."""
    raw = bx.keep_in_boxes()
    return bx.drop_contained(np.vstack([raw, bx.passage_boxes(raw), bx.tube_boxes(raw)]))


@lru_cache(maxsize=None)
def _robot_set(radius: float) -> bx.SafeSet:
    return _shrunk(tuple(np.full(3, radius)))


@lru_cache(maxsize=64)
def _shrunk(margin: tuple) -> bx.SafeSet:
    s = bx.shrink(_keep_in_region(), np.array(margin))
    s = s[np.all(bx.extent_rows(s) > 0.0, axis=1)]
    return bx.SafeSet(bx.drop_contained(s), np.array(margin))


def _in_region(pts: np.ndarray) -> np.ndarray:
    b = _keep_in_region()
    return np.any(np.all((pts[:, None, :] >= b[None, :, :3] - 1e-9)
                         & (pts[:, None, :] <= b[None, :, 3:] + 1e-9), axis=2), axis=1)


class _Formation:
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
        rs = _robot_set(self.radius)
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
        b = _keep_in_region()
        one = np.zeros(len(p), dtype=bool)
        for box in b:
            one |= np.all(lo >= box[:3] - 1e-9, axis=1) & np.all(hi <= box[3:] + 1e-9, axis=1)
        rest = np.flatnonzero(~one)
        if len(rest):
            pr, qr = p[rest], q[rest]
            m, k = len(pr), len(self.bag_pts)
            bp = np.repeat(pr, k, axis=0) + rot.rotate(np.repeat(qr, k, axis=0), np.tile(self.bag_pts, (m, 1)))
            bad = ~_in_region(bp)
            if bad.any():
                return f"the bag leaves the keep-in set at {np.round(bp[bad][0], 3).tolist()}"
        return None

    def turn_ok(self, p: np.ndarray, qa: np.ndarray, qb: np.ndarray) -> bool:
        qs = np.array([rot.slerp(qa, qb, s) for s in np.linspace(0.0, 1.0, TURN_CHECK_STEPS)])
        return self.safe_poses(np.tile(p, (len(qs), 1)), qs) is None


class _Limits:
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


def _angle(qa, qb) -> float:
    return float(rot.angle_between(qa, qb))


ROT_ANGLES = np.array([[_angle(a, b) for b in ROT_QUATS] for a in ROT_QUATS])


def _search(form: _Formation, lim: _Limits, p0, q0, p1, q1, forbidden: set):
    """Dijkstra over (orientation index, box index) nodes; returns the node path with points and
    entry kinds, or None."""
    restart = lim.v / lim.a          # a stop and restart costs about v/a seconds
    heap: list = []
    count = itertools.count()
    start_rot = [i for i in range(24) if _angle(q0, ROT_QUATS[i]) < 1e-6]
    for i in range(24):
        s = form.sets[form.cls[i]]
        th = _angle(q0, ROT_QUATS[i])
        if i not in start_rot and (("start", i) in forbidden or th > 2.1):
            continue
        cost = 0.0 if i in start_rot else lim.turn_time(th)
        for b in s.containing(p0):
            heapq.heappush(heap, (cost, next(count), (i, b), p0, None, "start"))
    done: dict = {}
    goal_rot = [i for i in range(24) if _angle(q1, ROT_QUATS[i]) < 1e-6]
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
        if bx.contains(box, p1):
            th = _angle(ROT_QUATS[i], q1)
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


def _narrow_hatch(form: _Formation, p0, p1) -> str:
    """Which hatch on the robot's own route is narrower than the formation's cross-section."""
    rs = planner.cached_safe_set(0.0)
    try:
        route = rs.boxes[rs.route(p0, p1)]
    except (bx.NoRoute, bx.OutsideSafeSet):
        return "no route joins start and goal even for one robot"
    best_cross = {}
    for name, h in _hatch_labels():
        on_route = any(np.all(bx.extent(bx.intersect(h, r)) > 0) for r in route)
        if not on_route:
            continue
        e = bx.extent(h)
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


def _violations(form: _Formation, robots, mode, centre: Trajectory, samples: int) -> list[str]:
    out = []
    t = np.linspace(0.0, centre.duration, samples)
    st = centre.sample(t)
    why = form.safe_poses(st.pos, st.quat)
    if why:
        out.append(why)
    for k, v in (("omega", mode.hard_limit_omega), ("alpha", mode.hard_limit_alpha)):
        peak = float(np.max(np.linalg.norm(getattr(st, k), axis=1)))
        if peak > v:
            out.append(f"the bag exceeds the {k} limit ({peak:.4g} > {v:.4g})")
    for i, r in enumerate(robots):
        rs = r.sample(t)
        for k, v in (("vel", mode.hard_limit_vel), ("acc", mode.hard_limit_accel)):
            peak = float(np.max(np.linalg.norm(getattr(rs, k), axis=1)))
            if peak > v:
                out.append(f"robot {i} exceeds the {k} limit ({peak:.4g} > {v:.4g})")
    return out


def default_bag_half() -> np.ndarray:
    return 0.5 * np.array(config.bags()["default"]["size"], dtype=float)


def plan_two_robots(start_centre, start_quat, goal_centre, goal_quat, offset,
                    flight_mode: str | None = None, face_forward: bool = True,
                    bag_size=None, samples: int = 4000) -> FormationPlan:
    """Plans for robots at +offset and -offset (bag frame) carrying a bag of `bag_size` (L, W, H
    in the bag frame; default config/bags.yaml) from a start to a goal bag pose, both at rest.
    face_forward is accepted for API symmetry: the formation always travels lined up with the
    corridor. Raises PlanError with a Motion code."""
    t_start = time.perf_counter()
    offset = np.asarray(offset, dtype=float)
    if offset.shape != (3,) or not np.all(np.isfinite(offset)):
        raise PlanError(INVALID_COMMAND, "offset must be a finite 3-vector")
    bag_half = default_bag_half() if bag_size is None else 0.5 * np.asarray(bag_size, dtype=float)
    if bag_half.shape != (3,) or not np.all(np.isfinite(bag_half)) or np.any(bag_half < 0):
        raise PlanError(INVALID_COMMAND, "bag_size must be three non-negative numbers")
    p0, p1 = planner.validate_point(start_centre, "start"), planner.validate_point(goal_centre, "goal")
    q0, q1 = planner.validate_quat(start_quat, "start"), planner.validate_quat(goal_quat, "goal")
    try:
        mode = flight_modes.get(flight_mode or None)
    except flight_modes.UnknownFlightMode as exc:
        raise PlanError(planner.INVALID_FLIGHT_MODE, str(exc)) from exc
    if not mode.control_enabled or mode.hard_limit_vel <= 0:
        raise PlanError(planner.INVALID_FLIGHT_MODE, f"flight mode {mode.name!r} does not allow motion")
    form = _Formation(offset, bag_half, bx.robot_radius())
    for p, q, name in ((p0, q0, "start"), (p1, q1, "goal")):
        why = form.safe_poses(p[None], q[None])
        if why:
            raise PlanError(VIOLATES_KEEP_IN, f"formation at the {name}: {why}")
    lim = _Limits(mode, form.lever)
    forbidden: set = set()
    for _ in range(MAX_SEARCHES):
        path = _search(form, lim, p0, q0, p1, q1, forbidden)
        if path is None:
            raise PlanError(PLAN_FAILED, "no formation plan: " + _narrow_hatch(form, p0, p1))
        bad = _first_bad_turn(form, path, q0, q1)
        if bad is None:
            break
        forbidden.add(bad)
    else:
        raise PlanError(PLAN_FAILED, "no formation plan: every turn found sweeps out of the keep-in set")
    items, route = _items(form, lim, path, p0, q0, p1, q1)
    best = None
    for overlap, stretch in TURN_OVERLAPS:   # turning while moving, and at rest (0, 1)
        traj, steps = _timeline(items, lim, p0, q0, overlap, stretch)
        if overlap > 0:
            # rotation and translation share the robots' acceleration: slow the whole plan
            # down uniformly (same path) until every limit holds
            k = _limit_scale(traj, offset, mode, samples) * 1.01
            if best is not None and traj.duration * k >= best[0].duration:
                continue
            traj = _scaled(traj, k)
            steps = steps + [f"all times x{k:.3f} (turns share the robots' acceleration)"]
        robots = [OffsetTrajectory(traj, offset), OffsetTrajectory(traj, -offset)]
        bad = _violations(form, robots, mode, traj, samples)
        if not bad and (best is None or traj.duration < best[0].duration):
            best = (traj, steps, robots)
    if best is None:
        raise PlanError(PLAN_FAILED, "formation plan fails its check: " + "; ".join(bad))
    traj, steps, robots = best
    traj.info.update(route=route, flight_mode=mode.name, steps=steps)
    centre = GlobalPlan(traj, None, route, time.perf_counter() - t_start)
    return FormationPlan(centre, robots, bag_half, steps)


def _first_bad_turn(form, path, q0, q1):
    """The forbidden-set key of the first turn of the path whose sweep is unsafe, else None."""
    (i0, _), pt0, _ = path[0]
    if _angle(q0, ROT_QUATS[i0]) > 1e-6 and not form.turn_ok(pt0, q0, ROT_QUATS[i0]):
        return ("start", i0)
    for (prev, _, _), (node, pt, kind) in zip(path[:-1], path[1:]):
        if kind == "turn":
            if not form.turn_ok(pt, ROT_QUATS[prev[0]], ROT_QUATS[node[0]]):
                return (prev, node)
    last = path[-2][0][0]
    if _angle(ROT_QUATS[last], q1) > 1e-6 and not form.turn_ok(path[-1][1], ROT_QUATS[last], q1):
        return ("goal", last)
    return None


def _limit_scale(traj: Trajectory, offset: np.ndarray, mode, samples: int) -> float:
    """Smallest uniform time scale (>= 1) after which the sampled robot speeds and accelerations
    and the bag's angular rates are within the flight mode's limits."""
    t = np.linspace(0.0, traj.duration, samples)
    st = traj.sample(t)
    k = max(1.0, float(np.max(np.linalg.norm(st.omega, axis=1))) / mode.hard_limit_omega,
            np.sqrt(float(np.max(np.linalg.norm(st.alpha, axis=1))) / mode.hard_limit_alpha))
    for sign in (1.0, -1.0):
        rs = OffsetTrajectory(traj, sign * offset).sample(t)
        k = max(k, float(np.max(np.linalg.norm(rs.vel, axis=1))) / mode.hard_limit_vel,
                np.sqrt(float(np.max(np.linalg.norm(rs.acc, axis=1))) / mode.hard_limit_accel))
    return k


def _scaled(traj: Trajectory, k: float) -> Trajectory:
    """The same path flown k times slower (every piece's start and duration times k)."""
    pos = [BezierPiece(p.points, p.t0 * k, p.duration * k) for p in traj.position]
    att = [QuaternionPolynomial(a.coefficients, a.t0 * k, a.duration * k) for a in traj.attitude]
    return Trajectory(pos, att, traj.t_offset, dict(traj.info))


def _items(form, lim, path, p0, q0, p1, q1) -> tuple[list, list[int]]:
    """The searched path as ("leg", orientation index, spline, a, b) and ("turn", point, qa, qb)
    items in order; legs planned by the global planner in their orientation's safe boxes."""
    items: list = []
    route: list[int] = []

    def turn(p, qa, qb):
        if _angle(qa, qb) >= 1e-6:
            items.append(("turn", p, qa, qb))

    def leg(i, box_ids, pa, pb):
        if np.linalg.norm(pb - pa) < 1e-4:
            return
        s = form.sets[form.cls[i]]
        safe = bx.SafeSet(s.boxes[box_ids], s.margin)
        try:
            pp = plan_position(pa, pb, lim.v, lim.a, safe)
        except (PlanningError, bx.NoRoute, bx.OutsideSafeSet) as exc:
            raise PlanError(PLAN_FAILED, f"formation leg {np.round(pa, 2).tolist()} -> "
                                         f"{np.round(pb, 2).tolist()}: {exc}") from exc
        items.append(("leg", i, pp.spline, pa, pb))
        route.extend(int(box_ids[k]) for k in pp.route)

    (i, b), _, _ = path[0]
    turn(p0, q0, ROT_QUATS[i])
    q = ROT_QUATS[i]
    cur_boxes, pa = [b], p0
    for node, pt, kind in path[1:]:
        if kind == "move":
            cur_boxes.append(node[1])
        elif kind == "turn":
            leg(i, cur_boxes, pa, pt)
            turn(pt, q, ROT_QUATS[node[0]])
            i, q = node[0], ROT_QUATS[node[0]]
            cur_boxes, pa = [node[1]], pt
        else:   # goal
            leg(i, cur_boxes, pa, p1)
            turn(p1, q, q1)
    return items, route


def _timeline(items, lim, p0, q0, overlap: float, stretch: float):
    """Trajectory of the bag centre from the items. A turn overlaps the end of the leg before it
    and the start of the leg after it by up to `overlap` x its own duration on each side (the
    formation turns while it slows down into and speeds up out of the turning point, where
    its translation is slowest), its duration stretched by `stretch` when it overlaps; with
    overlap 0 every turn is made at rest between the legs."""
    pos: list[BezierPiece] = []
    att: list[QuaternionPolynomial] = []
    steps: list[str] = []
    z = np.zeros(3)
    t = 0.0                     # end of the translation so far
    att_t, q_cur = 0.0, q0      # attitude defined up to att_t, q_cur from there
    p_cur = p0
    prev_leg_d = 0.0            # duration of the leg just flown (for the overlap)

    def hold_att(t_end):
        nonlocal att_t
        if t_end > att_t + 1e-9:
            att.append(QuaternionPolynomial.from_boundary(q_cur, z, z, q_cur, z, z, t_end - att_t, att_t))
            att_t = t_end

    pending = None              # a turn waiting for the next leg: (start, end)
    for k, it in enumerate(items):
        if it[0] == "turn":
            _, p, qa, qb = it
            nxt = items[k + 1] if k + 1 < len(items) else None
            T = lim.turn(qa, qb, 0.0).duration
            if overlap > 0:
                T *= stretch
            h_before = min(overlap * T, 0.45 * prev_leg_d, lim.v / lim.a)
            ts = max(att_t, t - h_before)
            hold_att(ts)
            poly = lim.turn(qa, qb, ts) if overlap == 0 else reorientation(
                qa, qb, lim.w, lim.al, t0=ts, min_duration=T)
            att.append(poly)
            att_t, q_cur = ts + poly.duration, qb
            nxt_d = nxt[2].duration if nxt is not None and nxt[0] == "leg" else 0.0
            h_after = min(overlap * poly.duration, 0.45 * nxt_d, lim.v / lim.a)
            t_next = max(t, att_t - h_after)
            moving = ts < t - 1e-9 or t_next < att_t - 1e-9
            steps.append(f"turn {np.degrees(_angle(qa, qb)):.0f} deg at {np.round(p, 2).tolist()} "
                         f"({poly.duration:.1f} s{', while moving' if moving else ''})")
            if t_next > t + 1e-9:       # hold the position while the turn needs it
                pos.append(BezierPiece(np.tile(p_cur, (8, 1)), t, t_next - t))
                t = t_next
        else:
            _, i, sp, pa, pb = it
            for j, t0 in enumerate(sp.t0):
                pos.append(BezierPiece(sp.points[j].copy(), t + t0, sp.durations[j]))
            steps.append(f"move {np.linalg.norm(pb - pa):.2f} m to {np.round(pb, 2).tolist()} "
                         f"({sp.duration:.1f} s)")
            t += sp.duration
            p_cur, prev_leg_d = pb, sp.duration
    if att_t > t + 1e-9:
        pos.append(BezierPiece(np.tile(p_cur, (8, 1)), t, att_t - t))
        t = att_t
    hold_att(t)
    if not pos:
        pos.append(BezierPiece(np.tile(p0, (8, 1)), 0.0, 1e-3))
        att.append(QuaternionPolynomial.from_boundary(q0, z, z, q0, z, z, 1e-3, 0.0))
    return Trajectory(pos, att), steps


# ---- formation plans from the robots' own poses (what planner_node serves) ---------------

@dataclass
class HeldTrajectory:
    """A robot holding one handle: at `offset` in the formation frame and turned by `relative`
    (its attitude in that frame), both fixed while the formation moves along `base`."""
    base: Trajectory
    offset: np.ndarray
    relative: np.ndarray

    @property
    def duration(self) -> float:
        return self.base.duration

    def sample(self, t) -> State:
        st = OffsetTrajectory(self.base, self.offset).sample(t)
        # rigidly attached: the same world-frame rates, the attitude turned by `relative`
        st.quat = rot.normalize(rot.multiply(st.quat, self.relative))
        return st

    def sample_rate(self, rate: float, max_states: int | None = None) -> State:
        """States every 1/rate s, end included; ValueError over max_states (None: no cap)."""
        if not rate > 0:
            raise ValueError("sample rate must be positive")
        d = self.duration
        if max_states is not None:
            check_sample_count(d, rate, max_states)
        t = np.arange(int(np.floor(d * rate + 1e-9)) + 1) / rate
        if t[-1] < d - 1e-9:
            t = np.append(t, d)
        return self.sample(t)


@dataclass
class RobotsPlan:
    """One trajectory per robot (request order) and the formation plan they come from."""
    robots: list[HeldTrajectory]
    formation: FormationPlan
    centre_start: np.ndarray
    centre_goal: np.ndarray


def plan_formation(starts, goal, bag_pose=None, bag_size=None,
                   flight_mode: str | None = None) -> RobotsPlan:
    """Formation plan for two robots holding one bag, from their start poses to the first
    robot's goal pose (the second keeps its place in the formation).

    starts: [(position, quaternion), (position, quaternion)] of the two robots, at rest;
    goal: (position, quaternion) of the first robot. The formation frame is the first robot's
    attitude, its centre the robots' midpoint. bag_pose (position, quaternion) places the bag:
    its box (bag_size, L W H in its own frame; default config/bags.yaml) is grown by its centre's
    distance from the midpoint and expressed in the formation frame, so the checked box holds
    the real one. Raises PlanError (INVALID_COMMAND for a bad request)."""
    if len(starts) != 2:
        raise PlanError(INVALID_COMMAND, f"a formation plan needs exactly two robots, got {len(starts)}")
    ps = [planner.validate_point(p, f"robot {i} start") for i, (p, _) in enumerate(starts)]
    qs = [planner.validate_quat(q, f"robot {i} start") for i, (_, q) in enumerate(starts)]
    g_p = planner.validate_point(goal[0], "goal")
    g_q = planner.validate_quat(goal[1], "goal")
    if np.linalg.norm(ps[0] - ps[1]) < 2 * bx.robot_radius() - 1e-6:
        raise PlanError(INVALID_COMMAND, f"robots 0 and 1 start {np.linalg.norm(ps[0] - ps[1]):.3f} m "
                                         f"apart: closer than two robot radii")
    q_c = qs[0]                                  # formation frame: the first robot's attitude
    centre = 0.5 * (ps[0] + ps[1])
    offset = rot.rotate_inverse(q_c, ps[0] - centre)
    rel = [rot.normalize(rot.multiply(rot.conjugate(q_c), q)) for q in qs]
    size = np.array(config.bags()["default"]["size"], float) if bag_size is None \
        else np.asarray(bag_size, float)
    if size.shape != (3,) or not np.all(np.isfinite(size)) or np.any(size < 0):
        raise PlanError(INVALID_COMMAND, "bag_size must be three non-negative numbers")
    half = 0.5 * size
    if bag_pose is not None:
        b_p = planner.validate_point(bag_pose[0], "bag")
        b_q = planner.validate_quat(bag_pose[1], "bag")
        r = rot.to_matrix(q_c).T @ rot.to_matrix(b_q)           # bag frame -> formation frame
        half = np.abs(r) @ half + np.abs(rot.rotate_inverse(q_c, b_p - centre))
    # the first robot's goal pose -> the formation frame's goal (robot 0 has rel = identity)
    goal_c = g_q
    goal_centre = g_p - rot.rotate(goal_c, offset)
    form = plan_two_robots(centre, q_c, goal_centre, goal_c, offset, flight_mode,
                           bag_size=2.0 * half)
    robots = [HeldTrajectory(form.centre.trajectory, offset, rel[0]),
              HeldTrajectory(form.centre.trajectory, -offset, rel[1])]
    return RobotsPlan(robots, form, centre, goal_centre)
