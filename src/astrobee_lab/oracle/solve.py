"""The oracle: could any controller have carried the pair to the goal at rest within the budget?

An offline optimal-control problem on the reduced pair model (astrobee_control.pair_model) with
the disturbance known in advance, solved by direct multiple shooting (CasADi + IPOPT): states
and body-wrench commands on a coarse grid (default 0.5 s, RK4 in 0.25 s substeps, a node at the
bump's start and end so the pulse is integrated exactly), per-axis wrench boxes of the flight
mode, the propulsion lag in the state, the robot's centre in the planner's safe boxes (keep-in
shrunk by the robot's radius) and the bag's 8 corners in the keep-in boxes shrunk by
`bag_margin` (each point's box is
the one holding it along the planned trajectory: the union of boxes is not convex, so the
assignment is fixed by the plan; a recovery through a different box is not searched). Only the
window from `lead` s before the bump to plan end + budget is solved, from the planned state with
the bag at rest behind the robot. Terminal set: over the last `hold` s the robot within the
goal's tolerances and robot and bag at rest (|v| < 1 cm/s, |w| < 0.02 rad/s, solved with a 20%
margin). Every constraint has an L1 slack (so IPOPT always returns a point); the answer is read
from the solution itself: feasible iff every constraint holds on the grid within 1 mm / the
thresholds.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from astrobee.task import REST_OMEGA, REST_SPEED   # the verdict's "at rest" (one owner)
from astrobee_control import pair_model as pm

MARGIN = 0.8                             # the NLP asks for 80% of the rest thresholds
BOX_TOL = 1e-3                           # m a point may sit outside its box and still count
LIMIT_AFTER = 1.0                        # s after the bump's end the mode's limits start
LIMIT_TOL = 1e-2                         # share a node's speed / rate may exceed the mode's
                                         # hard limit and still count (mode_limits)
BAG_MARGIN = 0.05                        # m the bag's corners keep from the walls: flown with
                                         # 0, the oracle's plans rode the bag along a wall
                                         # and the FEM bag touched it (bench/oracle_fly.py)
_KEEP: list = []                         # the last problems: CasADi caches the compiled
                                         # derivatives only while something holds them


@dataclass(frozen=True)
class Bump:
    """A force pulse on the bag's centre (world frame, N) from `time` for `duration` s."""

    time: float
    duration: float
    force: tuple


def bump_of_seed(seed: int, magnitude: float, duration: float = 0.2, t_min: float = 10.0,
                 t_max: float = 30.0, dt: float = 1.0 / 350.0) -> Bump:
    """The bump a study flight of this seed gets (the simulator's own disturbance schedule,
    astrobee_sim.realism_effects, so oracle rows pair with controller rows)."""
    from astrobee.realism import Disturbance, Realism
    from astrobee_sim.realism_effects import RealismEffects
    r = Realism(disturbances=(Disturbance(target="bag", magnitude=float(magnitude),
                                          duration=float(duration), t_min=t_min, t_max=t_max),))
    s = RealismEffects(r, int(seed), [""], dt, True).schedule()[0]
    return Bump(float(s["time"]), float(s["duration"]), tuple(float(f) for f in s["force"]))


@dataclass
class Leg:
    """A planned leg: the sampled reference (t, pos, vel, acc, quat) and the goal."""

    t: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    acc: np.ndarray
    quat: np.ndarray
    goal_position: np.ndarray
    goal_orientation: np.ndarray
    flight_mode: Any
    bag_size: np.ndarray

    @property
    def end(self) -> float:
        return float(self.t[-1])

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(position, velocity, accel, quaternion) of the plan at time t (held after its end)."""
        i = int(np.clip(np.searchsorted(self.t, t), 0, len(self.t) - 1))
        if t >= self.t[-1]:
            return self.goal_position, np.zeros(3), np.zeros(3), self.goal_orientation
        return self.pos[i], self.vel[i], self.acc[i], self.quat[i]


def plan_leg(scenario: str = "node2_to_jem_bag", rate: float = 10.0) -> Leg:
    """The leg the planner library gives a scenario (as Flight plans it)."""
    from astrobee import flight_modes
    from astrobee import rotations as rot
    from astrobee.scenario import Scenario
    from astrobee_planning import planner
    sc = Scenario.load(scenario)
    r0 = sc.robots[0]
    mode = flight_modes.get(sc.flight_mode)
    plan = planner.plan_global(np.asarray(r0.position), rot.normalize(np.asarray(r0.orientation)),
                               np.asarray(sc.goal_position), rot.normalize(np.asarray(sc.goal_orientation)),
                               mode.name, bool(sc.face_forward),
                               float(sc.carry_extent) if sc.carrying_bag else 0.0)
    st = plan.trajectory.sample_rate(rate)
    size = np.asarray(sc.bag.size if sc.bag else (0.5, 0.42, 0.25), float)
    return Leg(np.asarray(st.t), np.asarray(st.pos), np.asarray(st.vel), np.asarray(st.acc),
               np.asarray(st.quat), np.asarray(sc.goal_position, float),
               rot.normalize(np.asarray(sc.goal_orientation, float)), mode, size)


def planned_state(leg: Leg, p: pm.PairParams, t: float) -> np.ndarray:
    """The pair at plan time t: the robot on the plan, the bag at rest behind it, the lag's
    wrench the pair's feed-forward."""
    pos, vel, acc, q = leg.at(t)
    R = pm.rotation(np.asarray(q))
    f = (p.robot_mass + p.bag_mass) * (R.T @ acc)
    return pm.state(pos, vel, q, np.zeros(3), q, np.zeros(3), np.concatenate([f, np.zeros(3)]))


def bag_corners(size: np.ndarray) -> np.ndarray:
    h = 0.5 * np.asarray(size, float)
    return np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h


def _deepest(boxes: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Per point (K, 3), the box (index) it is deepest in (or nearest to, when in none)."""
    depth = np.minimum(pts[:, None, :] - boxes[None, :, :3], boxes[None, :, 3:] - pts[:, None, :])
    return np.argmax(depth.min(axis=2), axis=1)


@dataclass
class OracleResult:
    """The answer and the plan: feasible on the grid, violations, IPOPT's status and time."""

    feasible: bool
    status: str
    solve_time: float
    t: np.ndarray
    x: np.ndarray                 # (N+1, 26)
    u: np.ndarray                 # (N, 6) commanded body wrench per interval
    violation: dict = field(default_factory=dict)
    bump: Bump | None = None

    def row(self) -> dict:
        return {"feasible": self.feasible, "status": self.status,
                "solve_time": round(self.solve_time, 3), "nodes": len(self.t),
                **{k: round(float(v), 5) for k, v in self.violation.items()}}


def time_grid(t0: float, t_end: float, grid: float, bump: Bump | None) -> np.ndarray:
    cuts = [t0] + ([bump.time, bump.time + bump.duration] if bump else []) + [t_end]
    out = [t0]
    for a, b in zip(cuts[:-1], cuts[1:]):
        n = max(1, int(math.ceil((b - a) / grid - 1e-9)))
        out.extend(np.linspace(a, b, n + 1)[1:])
    return np.asarray(out)


def solve(leg: Leg, params: pm.PairParams, bump: Bump | None = None, budget: float = 30.0,
          grid: float = 0.5, lead: float = 1.0, t0: float | None = None, hold: float = 2.0,
          substep: float = 0.25, max_iter: int = 600, lag: float | None = None,
          x0: np.ndarray | None = None, jit: bool = True,
          bag_margin: float = BAG_MARGIN, guess: "OracleResult | None" = None,
          margin: float = MARGIN, mode_limits: bool = False) -> OracleResult:
    """Solve the oracle's problem (module docstring). t0: the window's start (default: `lead`
    s before the bump, or 0 without one); lag overrides params.lag; x0 the start state (default:
    the plan's at t0, planned_state); bag_margin (m) the bag's corners keep from the keep-in
    boxes' faces (the station's walls); guess: an earlier solution over this window (a replan)
    as the initial guess and for the box assignment instead of the planned leg; margin: the
    share of the terminal set's thresholds the NLP asks for (a plan to be flown wants room: the
    effort cost otherwise ends it on the NLP's edge); mode_limits: the robot's speed and body
    rate also within the flight mode's hard limits (hard_limit_vel, hard_limit_omega: the limits
    the laws plan their rates within) at every node from LIMIT_AFTER s after the bump's end;
    by default only the wrench is bounded."""
    import casadi as ca

    from .model import casadi_points, casadi_step
    from astrobee_planning import boxes as bx
    from astrobee_planning import planner

    if lag is not None:
        params = params.with_(lag=float(lag))
    if t0 is None:
        t0 = max(0.0, bump.time - lead) if bump else 0.0
    t_end = leg.end + budget
    ts = time_grid(t0, t_end, grid, bump)
    hs = np.diff(ts)
    N = len(hs)
    mode = leg.flight_mode
    lim = np.concatenate([np.asarray(mode.max_force, float), np.asarray(mode.max_torque, float)])
    corners = bag_corners(leg.bag_size)
    step = casadi_step(params, int(math.ceil(grid / substep)), jit)
    points = casadi_points(params, corners)
    # the plan as the initial guess and for the box assignment
    X0 = np.array([planned_state(leg, params, t) for t in ts]) if guess is None else \
        _resample(guess, ts)
    if x0 is not None:
        X0[0] = np.asarray(x0, float)
    pb, _ = pm.bag_centre(X0, params)
    Rb = pm.rotation(X0[:, pm.Q_B])
    guess_corners = pb[:, None, :] + np.einsum("nij,kj->nki", Rb, corners)
    safe = planner.cached_safe_set(0.0).boxes
    raw = bx.keep_in_boxes()
    keep = np.vstack([raw, bx.passage_boxes(raw)])
    robot_box = safe[_deepest(safe, X0[:, pm.P_R])]
    corner_box = keep[_deepest(keep, guess_corners.reshape(-1, 3))].reshape(len(ts), 8, 6)
    corner_box = corner_box + np.array([1, 1, 1, -1, -1, -1]) * float(bag_margin)

    opti = ca.Opti()
    X = opti.variable(pm.NX, N + 1)
    U = opti.variable(pm.NU, N)
    sb = opti.variable(N + 1)          # box slack per node (m)
    st = opti.variable()               # terminal slack (squared units)
    opti.subject_to(X[:, 0] == X0[0])
    effort = 0
    for k in range(N):
        d = list(bump.force) if bump and abs(ts[k] - bump.time) < 1e-9 else [0.0, 0.0, 0.0]
        opti.subject_to(X[:, k + 1] == step(X[:, k], U[:, k], ca.DM(d), float(hs[k])))
        opti.subject_to(opti.bounded(-lim, U[:, k], lim))
        effort += float(hs[k]) * ca.sumsqr(U[:, k] / lim)
    opti.subject_to(sb >= 0)
    opti.subject_to(st >= 0)
    # from a second after the bump's end (what the bump itself leaves is not a plan)
    if mode_limits:
        limited = [k for k in range(1, N + 1)
                   if bump is None or ts[k] >= bump.time + bump.duration + LIMIT_AFTER - 1e-9]
        sr = opti.variable(N + 1)      # rate / speed slack per node (squared units)
        opti.subject_to(sr >= 0)
        for k in limited:
            opti.subject_to(ca.sumsqr(X[pm.V_R, k]) <= float(mode.hard_limit_vel) ** 2 + sr[k])
            opti.subject_to(ca.sumsqr(X[pm.W_R, k]) <= float(mode.hard_limit_omega) ** 2 + sr[k])
        opti.set_initial(sr, 0.0)
    term = [k for k in range(N + 1) if ts[k] >= t_end - hold - 1e-9]
    gq = leg.goal_orientation
    tol_p, tol_a = float(mode.tolerance_pos), float(mode.tolerance_att)
    for k in range(N + 1):
        rc, bpts = points(X[:, k])
        opti.subject_to(opti.bounded(robot_box[k, :3] - sb[k], rc, robot_box[k, 3:] + sb[k]))
        for c in range(8):
            pc = bpts[3 * c:3 * c + 3]
            opti.subject_to(opti.bounded(corner_box[k, c, :3] - sb[k], pc, corner_box[k, c, 3:] + sb[k]))
        if k in term:
            xk = X[:, k]
            opti.subject_to(ca.sumsqr(xk[0:3] - leg.goal_position) <= (margin * tol_p) ** 2 + st)
            opti.subject_to(ca.dot(xk[6:10], gq) ** 2 >= math.cos(margin * tol_a / 2) ** 2 - st)
            opti.subject_to(ca.sumsqr(xk[3:6]) <= (margin * REST_SPEED) ** 2 + st)
            opti.subject_to(ca.sumsqr(xk[10:13]) <= (margin * REST_OMEGA) ** 2 + st)
            opti.subject_to(ca.sumsqr(xk[17:20]) <= (margin * REST_OMEGA) ** 2 + st)
    opti.minimize(1e3 * ca.sum1(sb) + 1e6 * st + 1e-2 * effort
                  + (1e6 * ca.sum1(sr) if mode_limits else 0))
    opti.set_initial(X, X0.T)
    U0 = X0[:-1, pm.A] if guess is None else \
        guess.u[np.clip(np.searchsorted(guess.t, ts[:-1] + 1e-9, side="right") - 1, 0, len(guess.u) - 1)]
    opti.set_initial(U, np.clip(U0, -lim, lim).T)
    opti.set_initial(sb, 0.0)
    opti.set_initial(st, 0.0)
    opti.solver("ipopt", {"print_time": bool(__import__("os").environ.get("ORACLE_TIME"))},
                {"print_level": 0, "max_iter": int(max_iter), "tol": 1e-6,
                 "acceptable_tol": 1e-4, "sb": "yes", "mu_strategy": "adaptive"})
    t_start = time.perf_counter()
    try:
        sol = opti.solve()
        status = "solved"
        xs, us = np.asarray(sol.value(X)).T, np.asarray(sol.value(U)).T
    except RuntimeError:
        status = opti.stats().get("return_status", "failed")
        xs, us = np.asarray(opti.debug.value(X)).T, np.asarray(opti.debug.value(U)).T
    solve_time = time.perf_counter() - t_start
    if jit:
        _KEEP[:] = _KEEP[-1:] + [opti]
    us = us.reshape(N, pm.NU)
    viol = violations(xs, ts, params, leg, robot_box, corner_box, corners, hold, t_end)
    ok = bool(np.all(np.isfinite(xs))) and viol["box"] <= BOX_TOL and viol["rest_speed"] < REST_SPEED \
        and viol["rest_omega"] < REST_OMEGA and viol["goal"] <= tol_p and viol["attitude"] <= tol_a
    if mode_limits:
        held = xs[limited] if limited else np.zeros((1, pm.NX))
        viol["speed_max"] = float(np.linalg.norm(held[:, pm.V_R], axis=1).max())
        viol["rate_max"] = float(np.linalg.norm(held[:, pm.W_R], axis=1).max())
        ok = ok and viol["speed_max"] <= float(mode.hard_limit_vel) * (1 + LIMIT_TOL) \
            and viol["rate_max"] <= float(mode.hard_limit_omega) * (1 + LIMIT_TOL)
    return OracleResult(ok, status, solve_time, ts, xs, us, viol, bump)


def _resample(res: OracleResult, ts: np.ndarray) -> np.ndarray:
    """res's states at times ts (linear between its nodes, quaternions renormalised)."""
    k = np.clip(np.searchsorted(res.t, ts, side="right") - 1, 0, len(res.t) - 2)
    s = np.clip((ts - res.t[k]) / (res.t[k + 1] - res.t[k]), 0.0, 1.0)[:, None]
    return pm.normalise((1 - s) * res.x[k] + s * res.x[k + 1])


def violations(xs: np.ndarray, ts: np.ndarray, p: pm.PairParams, leg: Leg, robot_box: np.ndarray,
               corner_box: np.ndarray, corners: np.ndarray, hold: float, t_end: float) -> dict:
    """What the solution breaks, measured on the grid: the largest box excursion (m), and over
    the last `hold` s the largest goal distance (m), attitude error (rad), the robot's speed (m/s,
    as the verdict) and the robot's and the bag's rates (rad/s: the pair at rest)."""
    from astrobee import rotations as rot
    pb, _ = pm.bag_centre(xs, p)
    Rb = pm.rotation(xs[:, pm.Q_B])
    pts = pb[:, None, :] + np.einsum("nij,kj->nki", Rb, corners)
    out_r = np.maximum(robot_box[:, :3] - xs[:, pm.P_R], xs[:, pm.P_R] - robot_box[:, 3:]).max()
    out_b = np.maximum(corner_box[..., :3] - pts, pts - corner_box[..., 3:]).max()
    term = ts >= t_end - hold - 1e-9
    xt = xs[term]
    goal = np.linalg.norm(xt[:, pm.P_R] - leg.goal_position, axis=1).max()
    att = max(rot.angle_between(q / np.linalg.norm(q), leg.goal_orientation) for q in xt[:, pm.Q_R])
    speed = np.linalg.norm(xt[:, pm.V_R], axis=1).max()
    omega = max(np.linalg.norm(xt[:, pm.W_R], axis=1).max(), np.linalg.norm(xt[:, pm.W_B], axis=1).max())
    return {"box": float(max(out_r, out_b, 0.0)), "goal": float(goal), "attitude": float(att),
            "rest_speed": float(speed), "rest_omega": float(omega)}
