"""Two robots carrying one two-handle bag as a rigid formation: robots at +offset and -offset
(bag frame) from the bag centre, the bag a box of half-extents `bag_half` around the centre.

Plan shape: the formation moves with its bag frame on one of the 24 axis-aligned orientations
(the robots in a line along a corridor, front/back handle, so a hatch only has to pass one robot
and the bag's cross-section) and turns in place, at rest, where a module has room. For an
axis-aligned orientation R the set of safe centres contains every keep-in box (plus passage and
tube boxes, see boxes.py) shrunk per axis by the formation's half-extent |R offset| + r (robot
spheres) and |R| bag_half (bag box); a translation leg is a time-optimal min-jerk spline
(position_planner) whose control points lie in those boxes, so both robots and the bag stay in
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

import time
from dataclasses import dataclass, field

import numpy as np

from astrobee import config, flight_modes, station
from astrobee import rotations as rot

from . import boxes as bx
from . import planner
from .errors import PlanError, PlanningError
from .formation_search import ROT_QUATS, Formation, Limits, angle, first_bad_turn, narrow_hatch, search
from .planner import INVALID_COMMAND, PLAN_FAILED, VIOLATES_KEEP_IN, GlobalPlan
from .position_planner import plan_position
from .quaternion_poly import QuaternionPolynomial, reorientation
from .trajectory import BezierPiece, State, Trajectory, check_sample_count

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


def _violations(form: Formation, robots, mode, centre: Trajectory, samples: int) -> list[str]:
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
    form = Formation(offset, bag_half, station.robot_radius())
    for p, q, name in ((p0, q0, "start"), (p1, q1, "goal")):
        why = form.safe_poses(p[None], q[None])
        if why:
            raise PlanError(VIOLATES_KEEP_IN, f"formation at the {name}: {why}")
    lim = Limits(mode, form.lever)
    forbidden: set = set()
    for _ in range(MAX_SEARCHES):
        path = search(form, lim, p0, q0, p1, q1, forbidden)
        if path is None:
            raise PlanError(PLAN_FAILED, "no formation plan: " + narrow_hatch(form, p0, p1))
        bad = first_bad_turn(form, path, q0, q1)
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
        if angle(qa, qb) >= 1e-6:
            items.append(("turn", p, qa, qb))

    def leg(i, box_ids, pa, pb):
        if np.linalg.norm(pb - pa) < 1e-4:
            return
        s = form.sets[form.cls[i]]
        safe = bx.SafeSet(s.boxes[box_ids], s.margin)
        try:
            pp = plan_position(pa, pb, lim.v, lim.a, safe)
        except PlanningError as exc:
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
            steps.append(f"turn {np.degrees(angle(qa, qb)):.0f} deg at {np.round(p, 2).tolist()} "
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
    if np.linalg.norm(ps[0] - ps[1]) < 2 * station.robot_radius() - 1e-6:
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
