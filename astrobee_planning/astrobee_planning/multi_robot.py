"""Two robots carrying one two-handle bag: a shared bag-centre plan, each robot at a fixed
body-frame offset from the centre (rotating with the plan's orientation, e.g. face-forward so
the formation lines up with the corridor).

The centre path is planned in the safe set shrunk by the robot radius plus `carry_extent`; each
robot's trajectory follows by rigid-body kinematics (p + R d, v + w x Rd,
a + alpha x Rd + w x (w x Rd)) and is checked by dense sampling against the robot safe set and
the flight mode's limits. On a violation the plan is retried with more clearance and then
with lower limits; when nothing passes, PlanError(PLAN_FAILED) says what failed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from astrobee import flight_modes
from astrobee import rotations as rot

from . import planner
from .planner import PLAN_FAILED, GlobalPlan, PlanError
from .trajectory import State, Trajectory


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
    centre: GlobalPlan
    robots: list[OffsetTrajectory]
    carry_extent: float
    limit_scale: float


def _violations(robots, mode, safe, samples: int) -> list[str]:
    out = []
    lim = {"vel": mode.hard_limit_vel, "acc": mode.hard_limit_accel}
    for i, r in enumerate(robots):
        st = r.sample(np.linspace(0.0, r.duration, samples))
        if not safe.contains_all(st.pos, tol=1e-9).all():
            out.append(f"robot {i} leaves the safe set")
        for k, v in lim.items():
            peak = float(np.max(np.linalg.norm(getattr(st, k), axis=1)))
            if peak > v:
                out.append(f"robot {i} exceeds the {k} limit ({peak:.4g} > {v:.4g})")
    return out


def plan_two_robots(start_centre, start_quat, goal_centre, goal_quat, offset,
                    flight_mode: str | None = None, face_forward: bool = True,
                    carry_extents=(0.0, 0.1, 0.2, 0.3), limit_scales=(1.0, 0.8, 0.6, 0.4),
                    samples: int = 3000) -> FormationPlan:
    """Plans for robots at +offset and -offset (body frame of the bag centre's orientation)."""
    offset = np.asarray(offset, dtype=float)
    if offset.shape != (3,) or not np.all(np.isfinite(offset)):
        raise PlanError(planner.INVALID_COMMAND, "offset must be a finite 3-vector")
    try:
        mode = flight_modes.get(flight_mode or None)
    except flight_modes.UnknownFlightMode as exc:
        raise PlanError(planner.INVALID_FLIGHT_MODE, str(exc)) from exc
    robot_safe = planner.cached_safe_set(0.0)
    for sign in (1.0, -1.0):
        for p, q in ((start_centre, start_quat), (goal_centre, goal_quat)):
            rp = np.asarray(p, float) + rot.rotate(rot.normalize(q), sign * offset)
            if not robot_safe.contains(rp):
                raise PlanError(planner.VIOLATES_KEEP_IN,
                                f"a robot at {np.round(rp, 3).tolist()} would be outside the keep-in set")
    tried: list[str] = []
    # the offset turns rotation into translation: keep |w| |d| and |alpha| |d| to half the limits
    d = float(np.linalg.norm(offset))
    ang = 1.0 if d == 0 else min(1.0, 0.5 * mode.hard_limit_vel / (mode.hard_limit_omega * d),
                                 0.5 * mode.hard_limit_accel / (mode.hard_limit_alpha * d))
    for ext in carry_extents:
        for scale in limit_scales:
            try:
                centre = planner.plan_global(start_centre, start_quat, goal_centre, goal_quat,
                                             mode.name, face_forward, ext, limit_scale=scale,
                                             angular_scale=ang)
            except PlanError as exc:
                tried.append(f"carry extent {ext}: {exc}")
                break          # a tighter safe set will not help at lower limits
            robots = [OffsetTrajectory(centre.trajectory, offset),
                      OffsetTrajectory(centre.trajectory, -offset)]
            bad = _violations(robots, mode, robot_safe, samples)
            if not bad:
                return FormationPlan(centre, robots, ext, scale)
            tried.append(f"carry extent {ext}, limit scale {scale}: {'; '.join(sorted(set(bad)))}")
            if not any("limit" in b for b in bad):
                break          # a geometry problem: try more clearance
    raise PlanError(PLAN_FAILED, f"no formation plan keeps both robots safe ({' | '.join(tried)})")
