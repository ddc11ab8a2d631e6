"""Full global plans (position + attitude) for a flight mode, with Astrobee result codes on failure.

plan_global(start_pos, start_quat, goal_pos, goal_quat, flight_mode, face_forward, carry_extent)
returns a GlobalPlan whose trajectory is: [rotate to the first heading, holding position] +
[translation, heading along the path] + [rotate to the goal orientation] when face_forward,
else one translation with a rest-to-rest blend of the orientation (the translation is
stretched when the rotation needs longer). Every limit of the flight mode is checked on a
dense sampling before returning.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from astrobee import flight_modes
from astrobee import rotations as rot

from . import attitude
from .boxes import SafeSet, safe_set
from .errors import NoRoute, OutsideSafeSet, PlanError, PlanningError
from .position_planner import Spline, plan_position
from .quaternion_poly import peak_rates_batch, reorientation
from .trajectory import BezierPiece, Trajectory

# Astrobee Motion action result codes (FACTS.md section 2)
SUCCESS = 1
ALREADY_THERE = 2
PLAN_FAILED = -1
INVALID_FLIGHT_MODE = -10
INVALID_COMMAND = -14
VIOLATES_KEEP_IN = -29

POS_EPS = 1e-3     # m: start and goal closer than this are the same position
ATT_EPS = 1e-3     # rad
QUAT_TOL = 1e-3    # tolerated |norm - 1| of a given quaternion


@dataclass
class GlobalPlan:
    trajectory: Trajectory
    spline: Spline | None          # the translation (None for a pure reorientation)
    route: list[int]
    planning_time: float
    code: int = SUCCESS


_safe_cache: dict[tuple, SafeSet] = {}


def cached_safe_set(carry_extent: float = 0.0) -> SafeSet:
    key = (round(float(carry_extent), 6),)
    if key not in _safe_cache:
        _safe_cache[key] = safe_set(carry_extent)
    return _safe_cache[key]


def validate_quat(q, name: str) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        raise PlanError(INVALID_COMMAND, f"{name} orientation must be 4 finite numbers")
    if abs(np.linalg.norm(q) - 1.0) > QUAT_TOL:
        raise PlanError(INVALID_COMMAND, f"{name} orientation is not a unit quaternion "
                                         f"(norm {np.linalg.norm(q):.6f})")
    return q / np.linalg.norm(q)


def validate_point(p, name: str) -> np.ndarray:
    p = np.asarray(p, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise PlanError(INVALID_COMMAND, f"{name} position must be 3 finite numbers")
    return p


def _hold(p: np.ndarray, t0: float, duration: float) -> BezierPiece:
    return BezierPiece(np.tile(p, (8, 1)), t0, duration)


def plan_global(start_pos, start_quat, goal_pos, goal_quat, flight_mode: str | None = None,
                face_forward: bool = False, carry_extent: float = 0.0,
                safe: SafeSet | None = None, limit_scale: float = 1.0,
                angular_scale: float = 1.0) -> GlobalPlan:
    """Plan from a start pose to a goal pose at rest; raises PlanError with a Motion code.
    limit_scale (0, 1] plans against a fraction of the mode's limits (e.g. for a formation);
    angular_scale (0, 1] lowers the angular limits further."""
    t_start = time.perf_counter()
    p0, p1 = validate_point(start_pos, "start"), validate_point(goal_pos, "goal")
    q0, q1 = validate_quat(start_quat, "start"), validate_quat(goal_quat, "goal")
    if not (np.isfinite(carry_extent) and carry_extent >= 0):
        raise PlanError(INVALID_COMMAND, "carry_extent must be a non-negative number")
    try:
        mode = flight_modes.get(flight_mode or None)
    except flight_modes.UnknownFlightMode as exc:
        raise PlanError(INVALID_FLIGHT_MODE, str(exc)) from exc
    if not mode.control_enabled or mode.hard_limit_vel <= 0:
        raise PlanError(INVALID_FLIGHT_MODE, f"flight mode {mode.name!r} does not allow motion")
    safe = safe if safe is not None else cached_safe_set(carry_extent)
    for p, name in ((p0, "start"), (p1, "goal")):
        if not safe.contains(p):
            raise PlanError(VIOLATES_KEEP_IN, f"{name} {np.round(p, 3).tolist()} is outside the "
                                              f"keep-in set shrunk by the robot"
                                              + (f" and a {carry_extent} m load" if carry_extent else ""))
    if not (0 < limit_scale <= 1 and 0 < angular_scale <= 1):
        raise PlanError(INVALID_COMMAND, "limit_scale and angular_scale must be in (0, 1]")
    wmax = mode.hard_limit_omega * limit_scale * angular_scale
    amax = mode.hard_limit_alpha * limit_scale * angular_scale
    if np.linalg.norm(p1 - p0) < POS_EPS:
        if rot.angle_between(q0, q1) < ATT_EPS:
            traj = Trajectory([_hold(p0, 0.0, 1e-3)], [reorientation(q0, q1, wmax, amax, 0.0, 1e-3)])
            return GlobalPlan(traj, None, [], time.perf_counter() - t_start, ALREADY_THERE)
        rp = reorientation(q0, q1, wmax, amax)
        traj = Trajectory([_hold(p0, 0.0, rp.duration)], [rp])
        return GlobalPlan(traj, None, [], time.perf_counter() - t_start)
    try:
        pp = plan_position(p0, p1, mode.hard_limit_vel * limit_scale,
                           mode.hard_limit_accel * limit_scale, safe)
    except OutsideSafeSet as exc:
        raise PlanError(VIOLATES_KEEP_IN, str(exc)) from exc
    except NoRoute as exc:
        raise PlanError(PLAN_FAILED, f"goal unreachable: {exc}") from exc
    except PlanningError as exc:
        raise PlanError(PLAN_FAILED, str(exc)) from exc
    spline = pp.spline
    if face_forward:
        traj = _face_forward_trajectory(spline, q0, q1, p0, p1, wmax, amax)
    else:
        traj = _blend_trajectory(spline, q0, q1, wmax, amax)
    traj.info.update(route=pp.route, solves=pp.solves, flight_mode=mode.name,
                     lower_bound=pp.lower_bound, qp_iterations=pp.iterations)
    _check_limits(traj, mode)
    return GlobalPlan(traj, spline, pp.route, time.perf_counter() - t_start)


def _spline_pieces(spline: Spline, t_offset: float) -> list[BezierPiece]:
    return [BezierPiece(spline.points[s].copy(), t_offset + t0, spline.durations[s])
            for s, t0 in enumerate(spline.t0)]


def _blend_trajectory(spline, q0, q1, wmax, amax) -> Trajectory:
    rp = reorientation(q0, q1, wmax, amax)
    if rp.duration > spline.duration:
        spline = spline.scaled(rp.duration / spline.duration)
    att = attitude.blend(q0, q1, spline.duration)
    return Trajectory(_spline_pieces(spline, 0.0), [att])


def _face_forward_trajectory(spline, q0, q1, p0, p1, wmax, amax) -> Trajectory:
    for _ in range(10):
        pieces, h0, h1 = attitude.face_forward(spline, 0.0)
        peaks_w, peaks_a = peak_rates_batch(pieces, 100)
        k = max(peaks_w / wmax, np.sqrt(peaks_a / amax))
        if k <= 0.995:
            break
        spline = spline.scaled(k * 1.02)
    r0 = reorientation(q0, h0, wmax, amax)
    t1 = r0.duration
    pieces, h0, h1 = attitude.face_forward(spline, t1)
    t2 = t1 + spline.duration
    r1 = reorientation(h1, q1, wmax, amax, t0=t2)
    pos = [_hold(p0, 0.0, t1)] + _spline_pieces(spline, t1) + [_hold(p1, t2, r1.duration)]
    return Trajectory(pos, [r0] + pieces + [r1])


def _check_limits(traj: Trajectory, mode) -> None:
    pk = traj.peaks()
    lim = {"vel": mode.hard_limit_vel, "acc": mode.hard_limit_accel,
           "omega": mode.hard_limit_omega, "alpha": mode.hard_limit_alpha}
    for k, v in pk.items():
        if v > lim[k] * (1 + 1e-6):
            raise PlanError(PLAN_FAILED, f"plan exceeds the {k} limit ({v:.4g} > {lim[k]:.4g})")
