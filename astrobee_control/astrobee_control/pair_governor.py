"""The governed pair law (`pair_gov`): PD on the robot's pose, made aware of the bag it carries.

The strap-held bag pivots on a ball joint at the gripper (~0.24 m from the robot's centre), so
(i) every force of the position loop that is not along the arm pulls the bag across the lever
and turns the robot, and (ii) a saturated attitude PD with 10 kg on the arm overshoots: its
switching line asks for rates the torque limits cannot brake. The law keeps PD's position loop
on the robot (the route through the hatch is the robot's) and changes, each by an option of
GovConfig (described at its field; all off by default but the rate limit):
- attitude: the wanted rate towards the reference is at most sqrt(2 a |e|) per axis, a the
  deceleration brake_share x the torque limits give on the pair's inertia; `momentum` damps
  the pair's rate instead of the robot's; `unwind` goes on round the long way when that ends
  sooner than braking and coming back (unwound_error);
- allocation (`lever`): the force's torque about the pair's centre counts, so the force may
  be bent to turn the pair (allocation.allocate) or only stop opposing the turn (`lever_use:
  guard`), as far as the walls (`clearance`, astrobee_control.clearance) and the route
  (`route_error`, `drift_speed`, `lever_along`) allow;
- the reference: the corridor fit (`fit`, astrobee_control.corridor_fit), the bag's line
  (`inline`, an ablation), the progress clock (`retime`);
- holding at the goal: the return capped (`hold_error`, `hold_error_upright`), with its own
  allocation and damping (`hold_lever_use`, `hold_torque_scale`, `hold_momentum`).
The laws the studies fly (gov_mom, gov_fit, gov_hold, gov_uw, gov_full, gov_uwu, gov_uwm (the
demo's)) are option sets written in studies/*.yaml. What each option measured, kept or not, is in
docs/results/pair_control_study.md (its appendix holds this module's development log) and
docs/results/pair_control_followup.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from astrobee import rotations as rot
from astrobee.flight_modes import FlightMode

from . import allocation
from .clearance import KeepIn, box_corners
from .corridor_fit import CorridorFit, pair_points
from .law import BagObservation, Step, carried_reference, check_hold_on_start, config_parameters
from .mass import MassProperties, box_inertia
from .pd import MODE_NOMINAL, Output, Reference, State
from .registry import Controller
from .tracking import CONTROLLING, STOPPING, Tracker

INERTIAS = ("robot", "pivot", "rigid", "centre")
LEVER_USES = ("help", "guard")
LEVER_ALONG = ("free", "brake", "route")
HOLD_LEVER_USES = ("same",) + LEVER_USES + ("guard_clear",)
TRACKED = ("robot", "centre")
LEVER_FROM = ("grasp", "bag")
CLEARANCE_MOTIONS = ("points", "drift")
UNWIND_RATES = ("damped", "pair")


@dataclass
class GovConfig:
    """The governed pair law's parameters (also the node's ROS parameters of the same names)."""

    grasp: tuple = (-0.234, 0.0, -0.065)  # m, the grasp point, robot body frame
    inertia: str = "rigid"       # the attitude loop's inertia (module docstring)
    momentum: float = 0.0        # 0..1: the rate the attitude loop damps while a segment is
                                 # followed: the robot's (0) or the pair's, its angular
                                 # momentum over its inertia (1)
    hold_momentum: float = 0.0   # ... and while stopping and holding at the goal (0: the
                                 # robot's own rate, which damps the bag's swing against it)
    inertia_scale: float = 1.0   # x that inertia (ablation: 0.8 / 1.2)
    brake_share: float = 0.6     # share of the torque limit the rate limit plans to brake with
    lever: bool = False          # the force's torque through the grasp counts in the allocation
    lever_use: str = "help"      # with lever: "help" (the force may be bent to make torque,
                                 # allocation.allocate) or "guard" (it only stops opposing a
                                 # saturated attitude torque, allocation.guard)
    lever_along: str = "free"    # with lever while a segment is followed: the force's
                                 # component along the route is the allocation's ("free"), at
                                 # most the position loop's ("brake": the lever may slow the
                                 # pair, never push it ahead) or the loop's ("route"); across
                                 # the route the lever bends it freely (allocation.keep_along)
    hold_lever_use: str = "same"  # ... while stopping and holding at the goal ("same": as
                                 # lever_use; "guard": the return force stops opposing the
                                 # turn upright, it is not bent to make torque there;
                                 # "guard_clear": the guard while the predicted clearance is
                                 # at least `clearance`, else help with its weight)
    lever_from: str = "grasp"    # the lever's point with `track: robot`: the grasp (the bag
                                 # follows on its joint) or the observed bag ("bag": the pair
                                 # rigid as it is now, a folded bag's centre included)
    track: str = "robot"         # the position loop's point: the robot's centre, or the pair's
                                 # centre of mass ("centre": turning the pair about it costs no
                                 # force, so the position loop stops fighting the attitude loop)
    w_torque: float = 3.0        # allocation: torque weight (force weight 1) at full attitude share
    hold_torque_scale: float = 1.0  # x w_torque while stopping and holding at the goal (the
                                 # lever's turn there moves the pair's centre near the JEM's walls)
    attitude_share: float = 3.0  # ... reached at this multiple of the attitude tolerance
    route_error: float = 0.0     # m: the force weight grows as (position error / this) past
                                 # it, so the route wins back over the lever (0: constant)
    drift_speed: float = 0.0     # m/s: the force weight grows as (the pair's centre's speed off
                                 # its reference / this)^2 past it, so the bump's momentum is
                                 # taken out before the lever turns the pair (0: off)
    hold_drift_speed: float = 0.0  # ... and while stopping and holding at the goal
    hold_error: float = 0.0      # m: the position error the loop sees while stopping and holding
                                 # is capped at this, so a pair far off its goal comes back at
                                 # ~ Kp/Kd x this with a small force, whose torque about the
                                 # pair's centre the attitude loop can hold (0: no cap)
    hold_error_upright: float = 0.0  # m: ... and once the pair is upright (attitude error
                                 # below half the mode's tolerance; ramped up to it from the
                                 # tolerance), so a pair carried far off comes home at the
                                 # mode's speed, not Kp/Kd x hold_error (0: hold_error)
    clearance: float = 0.0       # m: the force weight grows as (this / predicted clearance)^2
                                 # below it: the bag's corners and the robot's faces, each
                                 # carried on by its velocity for the time the force limits
                                 # need to stop it (0: off)
    stop_share: float = 0.5      # share of the force limit the stopping time is planned with
    clearance_motion: str = "points"  # what the clearance carries on: each point at its own
                                 # velocity ("points") or the pair as it is, at its centre's
                                 # velocity off the reference ("drift": the bag's swing on its
                                 # strap and the planned motion are not a drift to stop)
    retime: bool = False         # the progress clock (False: follow the plan's clock)
    att_slow: float = 0.15       # rad: attitude error where the progress starts to slow ...
    att_stop: float = 0.35       # ... and where it stops
    rate_slow: float = 0.04      # rad/s: robot rate where it starts to slow ...
    rate_stop: float = 0.10      # ... and stops
    swing_slow: float = 0.03     # m/s: bag speed relative to the robot where it starts ...
    swing_stop: float = 0.08     # ... and stops
    sigma_rate: float = 0.5      # 1/s: how fast the progress rate may rise (it falls at once)
    max_delay: float = 15.0      # s the route may fall behind the plan's clock (then it goes on)
    inline: bool = False         # the robot's reference across the strap is the bag's line:
                                 # where the grasp holds the bag's centre of percussion straight
                                 # behind it (the point a force at the grasp across the strap
                                 # does not move), steered back to the route while the route
                                 # accelerates along the strap (pair_governor.inline_reference)
    inline_max: float = 10.0     # m: the inline reference's largest distance off the route
    steer_kp: float = 0.05       # 1/s^2: that steering's gains on the percussion point's
    steer_kd: float = 0.3        # 1/s   route error ...
    steer_max: float = 0.3       # rad: ... through a fold of at most this
    steer_accel: float = 0.002   # m/s^2: along-strap acceleration below which it does not steer
    fit: float = 0.0             # m: the corridor fit's largest shift of the robot's reference
                                 # across the route, so the pair as it is now (the folded bag,
                                 # turning at the pair's rate) keeps off the walls ahead
                                 # (astrobee_control.corridor_fit; 0: off)
    fit_horizon: float = 4.0     # s of the plan ahead the fit looks at
    fit_speed: float = 0.05      # m/s: how fast the shift may move
    fit_margin: float = 0.1      # m: clearance beyond which a larger shift buys nothing
    unwind: bool = False         # a pair turning away from its reference goes on round the
                                 # long way (2 pi - the error) when that reaches it sooner than
                                 # braking and coming back (pair_governor.unwound_error)
    unwind_rate: str = "damped"  # the turn the long way round is decided on: the attitude
                                 # loop's damped rate ("damped", momentum / hold_momentum) or
                                 # the pair's always ("pair": the robot swinging against the
                                 # bag it holds is not the pair turning)
    unwind_coast: float = 0.0    # rad/s: a pair turning towards its reference (either way
                                 # round) faster than the mode's hard rate limit keeps that rate,
                                 # up to this, braked only to stop there (0: braked to the limit)
    unwind_within: float = 0.0   # rad: the long way round is taken up only while the attitude
                                 # error is below this: a bumped spin from near upright, not a
                                 # turn that grows later, when going round leaves too little
                                 # time (0: at any error). gov_uwu = gov_uw + 0.2, fresh
                                 # seeds 380-419: 5 N 35/40, 7.5 N 26/40 vs PD 11/40, 10 N
                                 # 27/40 vs 9/40 (studies/unwind_within.yaml)
    unwind_margin: float = 1.0   # the long way round is taken up only when it ends in at most
                                 # this share of braking's time: at the bump the rate grows
                                 # through the tie, and a small bump's full rate leaves going
                                 # round only a little sooner (0.8-0.9 at 5 N against 0.6-0.7 at
                                 # 7.5 N, traced), where braking with the lever is sooner still
                                 # gov_uwm = gov_uw + 0.8, fresh seeds 420-459: 5 N 36/40, 7.5 N
                                 # 24/40 vs PD 11/40, 10 N 27/40 vs 9/40; the clamp at 5 N 1
                                 # contact flight vs 0 (studies/unwind_margin.yaml); again on
                                 # 460-499: 36/40, 28/40 vs 12/40, 28/40 vs 8/40, clamp 0 vs 0
                                 # (studies/unwind_margin_replication.yaml)
    unwind_brake_scale: float = 1.0  # the long way round is weighed against braking at the
                                 # brake_share deceleration x this (the lever's force helps
                                 # the torque brake a small turn) ...
    unwind_brake_within: float = 0.0  # rad: ... where braking so stops the turn within this
                                 # of the reference (past ~0.4 rad braking with the bag
                                 # trailing is an inverted pendulum; 0: everywhere). Not
                                 # kept: x 3 within 0.6 / 1.0 rad flew gov_uw's 5 N outcomes
                                 # and lost 1-3 net at 7.5 N (studies/unwind_brake.yaml)
    keep_direction: bool = False  # a force wanted past the limits is scaled into them along
                                 # its own direction before the allocation: clipping each axis
                                 # turns it (traced, clamp 5 N seed 437: the hold's return force
                                 # along body -y came out mostly -x, into the JEM's wall).
                                 # Fresh seeds 500-539: against gov_uwm 3 / 3 on the clamp and
                                 # 4 / 4 at 10 N, no count changes (studies/keep_direction.yaml)
    settle_time: float = 5.0

    def validate(self) -> "GovConfig":
        """Raise ValueError (one line) for a value the law cannot run with."""
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "grasp":
                if len(v) != 3 or not all(isinstance(x, (int, float)) and math.isfinite(x)
                                          for x in v):
                    raise ValueError(f"grasp must be three finite numbers (m), got {v!r}")
            elif f.name == "inertia":
                if v not in INERTIAS:
                    raise ValueError(f"inertia must be one of {', '.join(INERTIAS)}, got {v!r}")
            elif f.name == "lever_use":
                if v not in LEVER_USES:
                    raise ValueError(f"lever_use must be one of {', '.join(LEVER_USES)}, got {v!r}")
            elif f.name == "lever_along":
                if v not in LEVER_ALONG:
                    raise ValueError(f"lever_along must be one of {', '.join(LEVER_ALONG)}, "
                                     f"got {v!r}")
            elif f.name == "hold_lever_use":
                if v not in HOLD_LEVER_USES:
                    raise ValueError(f"hold_lever_use must be one of "
                                     f"{', '.join(HOLD_LEVER_USES)}, got {v!r}")
            elif f.name == "lever_from":
                if v not in LEVER_FROM:
                    raise ValueError(f"lever_from must be one of {', '.join(LEVER_FROM)}, "
                                     f"got {v!r}")
            elif f.name == "clearance_motion":
                if v not in CLEARANCE_MOTIONS:
                    raise ValueError(f"clearance_motion must be one of "
                                     f"{', '.join(CLEARANCE_MOTIONS)}, got {v!r}")
            elif f.name == "unwind_rate":
                if v not in UNWIND_RATES:
                    raise ValueError(f"unwind_rate must be one of {', '.join(UNWIND_RATES)}, "
                                     f"got {v!r}")
            elif f.name == "track":
                if v not in TRACKED:
                    raise ValueError(f"track must be one of {', '.join(TRACKED)}, got {v!r}")
            elif f.name in ("lever", "retime", "inline", "unwind", "keep_direction"):
                if not isinstance(v, (bool, np.bool_)):
                    raise ValueError(f"{f.name} must be true or false, got {v!r}")
            elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v < 0:
                raise ValueError(f"{f.name} must be a finite number >= 0, got {v!r}")
        for name in ("inertia_scale", "settle_time", "sigma_rate", "fit_horizon", "fit_speed",
                     "hold_torque_scale", "unwind_brake_scale", "unwind_margin"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("momentum", "hold_momentum"):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(f"{name} must be in [0, 1], got {getattr(self, name)!r}")
        if self.hold_lever_use == "guard_clear" and not (self.lever and self.clearance > 0):
            raise ValueError("hold_lever_use guard_clear needs lever true and clearance > 0")
        if self.hold_error_upright > 0 and not self.hold_error_upright >= self.hold_error > 0:
            raise ValueError(f"hold_error_upright ({self.hold_error_upright}) needs hold_error > 0 "
                             f"and at most itself, got hold_error {self.hold_error}")
        if not 0 < self.brake_share <= 1:
            raise ValueError(f"brake_share must be in (0, 1], got {self.brake_share!r}")
        if not 0 < self.stop_share <= 1:
            raise ValueError(f"stop_share must be in (0, 1], got {self.stop_share!r}")
        for a, b in (("att_slow", "att_stop"), ("rate_slow", "rate_stop"),
                     ("swing_slow", "swing_stop")):
            if not getattr(self, a) < getattr(self, b):
                raise ValueError(f"{a} ({getattr(self, a)}) must be below {b} "
                                 f"({getattr(self, b)})")
        return self

    @classmethod
    def from_params(cls, params: dict) -> "GovConfig":
        names = {f.name for f in fields(cls)}
        return cls(**{k: (tuple(v) if k == "grasp" else v) for k, v in params.items()
                      if k in names}).validate()


def rate_limited(e: np.ndarray, k: np.ndarray, alpha_max: np.ndarray, w_max: float
                 ) -> np.ndarray:
    """The body rate wanted towards an attitude error e: k e, at most sqrt(2 alpha e) per axis
    (the robot can still brake to rest at the reference) and w_max."""
    mag = np.abs(e)
    return np.sign(e) * np.minimum(k * mag, np.minimum(np.sqrt(2.0 * alpha_max * mag), w_max))


def turn_time(angle: float, v: float, alpha: float, w_max: float = math.inf) -> float:
    """The least time (s) to turn `angle` (rad) and stop, starting at `v` rad/s towards it
    (negative: away), at +-alpha rad/s^2 and at most w_max rad/s (bang-coast-bang; a start
    faster than w_max towards it is taken as w_max: an estimate, not a plan)."""
    if v < 0:                                  # stop first, then turn the angle grown meanwhile
        return -v / alpha + turn_time(angle + v * v / (2 * alpha), 0.0, alpha, w_max)
    v = min(v, w_max)
    peak = math.sqrt(v * v / 2 + alpha * angle)
    if v * v / (2 * alpha) > angle:            # too fast to stop in time: overshoot and come back
        over = v * v / (2 * alpha) - angle
        return v / alpha + turn_time(over, 0.0, alpha, w_max)
    if peak <= w_max:
        return (2 * peak - v) / alpha
    d_acc, d_dec = (w_max ** 2 - v * v) / (2 * alpha), w_max ** 2 / (2 * alpha)
    return (w_max - v) / alpha + (angle - d_acc - d_dec) / w_max + w_max / alpha


def unwound_error(e: np.ndarray, w: np.ndarray, alpha_max: np.ndarray, w_max: float,
                  unwinding: bool, w_keep: float = 0.0, brake_scale: float = 1.0,
                  brake_within: float = 0.0, start_within: float = 0.0, margin: float = 1.0
                  ) -> tuple[np.ndarray, bool]:
    """The attitude error to steer by and whether it is the long way round: a pair turning away
    from its reference at w (body rad/s) about the error's axis goes on round (the error
    e - 2 pi e / |e|) when that turn, at most w_max, ends sooner than stopping and coming back,
    or when it already went that way (`unwinding`) and still turns away. w_max: the flight
    mode's hard rate limit, which the long way round coasts at (or at the turn's own rate, up
    to w_keep, where that is faster: GovConfig.unwind_coast). The oracle's 7.5 N
    recoveries do this (docs/results/pair_control_followup.md): the torque limits stop the
    bumped pair's turn only ~1.2 rad later, and the way back then costs more than the way on.
    brake_scale: the short way's deceleration x this (the lever's force helping the torque),
    where braking so would stop the turn within brake_within rad of the reference (0: always).
    start_within: the long way round is taken up only while the error is below this (rad; 0:
    at any error): a turn that grows later is braked. margin: ... and only when it ends in at
    most this share of braking's time (1: whichever is sooner; below 1 a near tie is braked)."""
    th = float(np.linalg.norm(e))
    if th < 1e-6:
        return e, False
    u = e / th
    v = float(w @ u)                           # rate towards the reference the short way
    if v >= 0:
        return e, False
    if unwinding:                              # went that way and still turns away
        return e - 2 * math.pi * u, True
    if 0 < start_within < th:                  # grown too far to take the long way up now
        return e, False
    a = 1.0 / float((u * u) @ (1.0 / np.asarray(alpha_max, float)))
    w_round = max(w_max, min(-v, w_keep))
    a_brake = a * brake_scale
    if brake_within > 0 and th + v * v / (2 * a_brake) > brake_within:
        a_brake = a
    if turn_time(2 * math.pi - th, -v, a, w_round) < margin * turn_time(th, v, a_brake):
        return e - 2 * math.pi * u, True
    return e, False


def scaled_into(v: np.ndarray, lim: np.ndarray) -> np.ndarray:
    """v scaled down along its own direction until every component is within +-lim."""
    over = float(np.max(np.abs(v) / lim))
    return v / over if over > 1.0 else v


def ramp(x: float, lo: float, hi: float) -> float:
    """1 below lo, 0 above hi, linear between."""
    return float(np.clip((hi - x) / (hi - lo), 0.0, 1.0))


class GovController:
    """One wrench per state and reference (the PdFeedback interface the Tracker drives)."""

    def __init__(self, flight_mode: FlightMode, mass: MassProperties, config: GovConfig) -> None:
        self.flight_mode = flight_mode
        self.mass = mass                   # the robot's own
        self.config = config
        self.bag: BagObservation | None = None
        self.swing_speed = 0.0             # m/s, bag relative to the robot (last observation)
        self._rest = None                  # body-frame bag offset when first observed (the fold's
                                           # reference)
        self._keep_in = None               # clearance.KeepIn, built on first use
        self.following = False             # a segment is followed (the inline reference is on)
        self.shift = (np.zeros(3), np.zeros(3))   # the corridor fit's (shift, its velocity)
        self.unwinding = False             # the attitude loop goes the long way round

    def reset(self) -> None:
        """Nothing integrates."""

    def set_flight_mode(self, mode: FlightMode) -> None:
        self.flight_mode = mode

    def set_mass(self, mass: MassProperties) -> None:
        self.mass = mass

    def figures(self) -> tuple[float, np.ndarray, np.ndarray]:
        """(pair mass, the force's lever through the grasp, the attitude loop's inertia)."""
        cfg = self.config
        m_r, I_r = float(self.mass.mass), np.asarray(self.mass.inertia, float)
        bag = self.bag
        if bag is None or bag.mass <= 0:
            return m_r, np.zeros(3), I_r * cfg.inertia_scale
        m_b = float(bag.mass)
        M = m_r + m_b
        g = np.asarray(cfg.grasp, float)
        lever = np.zeros(3)
        if cfg.lever:
            lever = (m_b / M) * (np.asarray(self._offset, float)
                                 if cfg.track == "centre" or cfg.lever_from == "bag" else g)
        if cfg.inertia == "robot":
            inertia = I_r
        elif cfg.inertia == "centre":
            inertia = self.pair_inertia()
        elif cfg.inertia == "pivot":
            mu = m_r * m_b / M
            inertia = I_r + mu * (g @ g * np.eye(3) - np.outer(g, g))
        else:
            d = np.asarray(self._offset, float)
            inertia = I_r + box_inertia(m_b, bag.size) + m_b * (d @ d * np.eye(3) - np.outer(d, d))
        return M, lever, inertia * cfg.inertia_scale

    def pair_inertia(self) -> np.ndarray:
        """The pair's inertia about its centre of mass as it is now (robot body frame)."""
        bag = self.bag
        m_r, m_b = float(self.mass.mass), float(bag.mass)
        d = np.asarray(self._offset, float)
        Rb = self._bag_rot
        return (np.asarray(self.mass.inertia, float) + Rb @ box_inertia(m_b, bag.size) @ Rb.T
                + m_r * m_b / (m_r + m_b) * (d @ d * np.eye(3) - np.outer(d, d)))

    def pair_rate(self, state: State) -> np.ndarray:
        """The pair's angular momentum about its centre over its inertia (body frame, rad/s)."""
        bag = self.bag
        R = rot.to_matrix(rot.normalize(state.orientation))
        m_r, m_b = float(self.mass.mass), float(bag.mass)
        M = m_r + m_b
        d = R @ np.asarray(self._offset, float)              # robot -> bag, world
        dv = np.asarray(bag.velocity, float) - np.asarray(state.velocity, float)
        Rb = R @ self._bag_rot
        I_r = R @ np.asarray(self.mass.inertia, float) @ R.T
        I_b = Rb @ box_inertia(m_b, bag.size) @ Rb.T
        H = I_r @ (R @ np.asarray(state.omega, float)) + I_b @ np.asarray(bag.omega, float) \
            + (m_r * m_b / M) * np.cross(d, dv)
        I_c = I_r + I_b + (m_r * m_b / M) * (d @ d * np.eye(3) - np.outer(d, d))
        return R.T @ np.linalg.solve(I_c, H)

    def centre_errors(self, state: State, ref: Reference, R: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
        """(position, velocity) error of the pair's centre of mass against the reference's (the
        robot's reference carrying the bag at its present body-frame offset; world frame)."""
        m_r, m_b = float(self.mass.mass), float(self.bag.mass)
        c = (m_b / (m_r + m_b)) * np.asarray(self._offset, float)
        p_ref, v_ref = carried_reference(ref, c)
        v_c = (m_r * np.asarray(state.velocity, float)
               + m_b * np.asarray(self.bag.velocity, float)) / (m_r + m_b)
        return p_ref - np.asarray(state.position, float) - R @ c, v_ref - v_c

    def observe(self, bag: BagObservation | None, robot: State | None) -> None:
        if bag is None or not bag.attached or robot is None or bag.mass <= 0:
            self.bag, self.swing_speed, self._rest = None, 0.0, None
            return
        self.bag = bag
        self._offset, self._bag_rot = bag.offset_in(robot)
        if self._rest is None:
            self._rest = np.array(self._offset, float)
        self.swing_speed = float(np.linalg.norm(np.asarray(bag.velocity, float)
                                                - np.asarray(robot.velocity, float)))

    def inline_reference(self, state: State, ref: Reference, R: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
        """The robot's (position, velocity) reference with its part across the strap moved onto
        the bag's line. On a ball joint in free fall the bag's centre of percussion q (1/k =
        I_grasp / (m_b L) from the grasp along the strap) moves only with the strap's tension,
        q'' = (a_grasp . n) (n - n0) across the route's direction n0: a force across the strap
        swings the bag about q but cannot take q back, so a robot held on its route keeps the bag
        folded (braking with it trailing makes the fold grow). Here the robot instead goes where
        the grasp holds q straight behind it, with a fold of at most steer_max wanted only while
        the plan accelerates along the strap, as far as it steers q back to the route."""
        cfg, bag = self.config, self.bag
        g = np.asarray(cfg.grasp, float)
        p_ref, v_ref = np.asarray(ref.position, float), np.asarray(ref.velocity, float)
        r0 = np.asarray(self._rest, float) - g
        grasp = np.asarray(state.position, float) + R @ g
        r = np.asarray(bag.position, float) - grasp
        L = float(np.linalg.norm(r))
        if L < 1e-3 or float(np.linalg.norm(r0)) < 1e-3:
            return p_ref, v_ref
        n = r / L
        m_b = float(bag.mass)
        Rb = R @ self._bag_rot
        I_w = Rb @ box_inertia(m_b, bag.size) @ Rb.T
        I_b = 0.5 * (float(np.trace(I_w)) - float(n @ I_w @ n))   # mean across the strap
        lq = (I_b + m_b * L * L) / (m_b * L)                       # grasp -> percussion point
        w_w = R @ np.asarray(state.omega, float)
        v_grasp = np.asarray(state.velocity, float) + np.cross(w_w, R @ g)
        v_rel = np.asarray(bag.velocity, float) - v_grasp
        q = grasp + lq * n
        q_dot = v_grasp + (lq / L) * (v_rel - (v_rel @ n) * n)
        R_ref = rot.to_matrix(rot.normalize(ref.orientation))
        w_ref = np.asarray(ref.omega, float)
        n0 = R_ref @ (r0 / float(np.linalg.norm(r0)))
        arm = R_ref @ g + lq * n0                                  # robot -> q on the route
        q_ref, q_ref_dot = p_ref + arm, v_ref + np.cross(w_ref, arm)
        across = np.eye(3) - np.outer(n0, n0)
        e, e_dot = across @ (q_ref - q), across @ (q_ref_dot - q_dot)
        a_n = float(np.asarray(ref.accel, float) @ n0)
        fold = np.zeros(3)
        if abs(a_n) > cfg.steer_accel:
            fold = (cfg.steer_kp * e + cfg.steer_kd * e_dot) / a_n
            size = float(np.linalg.norm(fold))
            if size > cfg.steer_max:
                fold *= cfg.steer_max / size
        # the robot where the grasp holds q along n0 + fold; only its part across n0 moves
        n_want = n0 + fold
        n_want /= float(np.linalg.norm(n_want))
        p_want = q - lq * n_want - R_ref @ g
        v_want = q_dot - np.cross(w_ref, R_ref @ g)
        shift, shift_v = across @ (p_want - p_ref), across @ (v_want - v_ref)
        size = float(np.linalg.norm(shift))
        if size > cfg.inline_max:            # no further off the route than this: on the cap,
            u = shift / size                  # the reference does not move outwards
            shift = u * cfg.inline_max
            shift_v = shift_v - max(float(shift_v @ u), 0.0) * u if cfg.inline_max > 0 \
                else np.zeros(3)
        return p_ref + shift, v_ref + shift_v

    def walls(self) -> tuple[KeepIn, float]:
        """The keep-in union (built on first use) and the robot's half-size (m)."""
        if self._keep_in is None:
            from astrobee import config as cfg_files
            self._keep_in = KeepIn(cfg_files.keep_in_boxes())
            self._robot_half = 0.5 * float(cfg_files.astrobee()["envelope"])
        return self._keep_in, self._robot_half

    def predicted_clearance(self, state: State, ref: Reference | None = None) -> float:
        """The least clearance (m) of the bag's corners and the robot's faces to the keep-in
        boxes, now and at the end of a stop at stop_share of the smallest force limit on the
        pair's mass (astrobee_control.clearance): each point carried on at its own velocity
        (`clearance_motion: points`), or all of them with the pair's centre's velocity off the
        reference's (`drift`; needs `ref`)."""
        self.walls()
        bag = self.bag
        M = float(self.mass.mass) + float(bag.mass)
        a = self.config.stop_share * float(np.min(self.flight_mode.max_force)) / M
        R_b = rot.to_matrix(rot.normalize(bag.orientation))
        corners = box_corners(bag.position, R_b, bag.size)
        v_b, v_r = np.asarray(bag.velocity, float), np.asarray(state.velocity, float)
        if self.config.clearance_motion == "drift" and ref is not None:
            R = rot.to_matrix(rot.normalize(state.orientation))
            v_b = v_r = -self.centre_errors(state, ref, R)[1]
        p_r = np.asarray(state.position, float)
        # now and at the stop (v t / 2, t = |v| / a), the bag's corners and the robot's centre in
        # one query
        pts = np.vstack([corners, corners + (0.5 * float(np.linalg.norm(v_b)) / a) * v_b,
                         p_r, p_r + (0.5 * float(np.linalg.norm(v_r)) / a) * v_r])
        d = self._keep_in.clearance(pts, 1.0)
        return float(min(d[:16].min(), d[16:].min() - self._robot_half))

    def step(self, state: State, ref: Reference, dt: float) -> Output:
        """The body wrench for `state` tracking the robot reference `ref`."""
        fm, cfg = self.flight_mode, self.config
        q = rot.normalize(state.orientation)
        R = rot.to_matrix(q)
        w = np.asarray(state.omega, float)
        M, lever, I = self.figures()
        if cfg.fit > 0:
            ref = replace(ref, position=np.asarray(ref.position, float) + self.shift[0],
                          velocity=np.asarray(ref.velocity, float) + self.shift[1])
        e_p = np.asarray(ref.position, float) - np.asarray(state.position, float)
        e_v = np.asarray(ref.velocity, float) - np.asarray(state.velocity, float)
        ec_p, ec_v = e_p, e_v
        if cfg.inline and self.following and self.bag is not None and self.bag.mass > 0:
            p_in, v_in = self.inline_reference(state, ref, R)
            ec_p = p_in - np.asarray(state.position, float)
            ec_v = v_in - np.asarray(state.velocity, float)
        elif cfg.track == "centre" and self.bag is not None:
            ec_p, ec_v = self.centre_errors(state, ref, R)
        if cfg.hold_error > 0 and not self.following:
            cap = cfg.hold_error
            if cfg.hold_error_upright > 0:
                up = ramp(rot.angle_between(q, ref.orientation), 0.5 * fm.tolerance_att,
                          fm.tolerance_att)
                cap += up * (cfg.hold_error_upright - cfg.hold_error)
            size = float(np.linalg.norm(ec_p))
            if size > cap:
                ec_p = ec_p * (cap / size)
        a_w = np.asarray(ref.accel, float) + fm.pos_kp * ec_p + fm.vel_kd * ec_v
        f_des = R.T @ (M * a_w)
        e_att = rot.attitude_error(q, ref.orientation)
        t_lim, f_lim = np.asarray(fm.max_torque, float), np.asarray(fm.max_force, float)
        alpha_max = cfg.brake_share * t_lim / np.diag(I)
        w_fb = w
        mix = cfg.momentum if self.following else cfg.hold_momentum
        if mix > 0 and self.bag is not None and self.bag.mass > 0:
            w_fb = (1 - mix) * w + mix * self.pair_rate(state)
        e_go, w_max = e_att, float(fm.hard_limit_omega)
        if (cfg.unwind or cfg.unwind_coast > 0) and self.bag is not None and self.bag.mass > 0:
            w_turn = w_fb
            if cfg.unwind_rate == "pair" and mix < 1:
                w_turn = self.pair_rate(state)
            w_turn = w_turn - R.T @ np.asarray(ref.omega, float)
            if cfg.unwind:
                e_go, self.unwinding = unwound_error(
                    e_att, w_turn, alpha_max, w_max, self.unwinding, cfg.unwind_coast,
                    cfg.unwind_brake_scale, cfg.unwind_brake_within, cfg.unwind_within,
                    cfg.unwind_margin)
            th = float(np.linalg.norm(e_go))
            if cfg.unwind_coast > 0 and th > 1e-6:     # keep a fast turn that goes the way on
                w_max = max(w_max, min(float(w_turn @ e_go) / th, cfg.unwind_coast))
        w_des = R.T @ np.asarray(ref.omega, float) + rate_limited(
            e_go, fm.att_kp / fm.omega_kd, alpha_max, w_max)
        al_b = R.T @ np.asarray(ref.alpha, float) + fm.omega_kd * (w_des - w_fb)
        tau_des = I @ al_b + np.cross(w, I @ w)
        if fm.control_enabled:
            share = float(np.clip(np.linalg.norm(e_att) / (cfg.attitude_share *
                                                           fm.tolerance_att), 0.1, 1.0))
            w_f = 1.0
            if cfg.route_error > 0:
                w_f = max(1.0, float(np.linalg.norm(e_p)) / cfg.route_error)
            drift = cfg.drift_speed if self.following else cfg.hold_drift_speed
            if drift > 0 and self.bag is not None and self.bag.mass > 0:
                v_off = float(np.linalg.norm(self.centre_errors(state, ref, R)[1]))
                w_f = max(w_f, (v_off / drift) ** 2)
            use = cfg.lever_use
            if not self.following and cfg.hold_lever_use != "same":
                use = cfg.hold_lever_use
            if cfg.clearance > 0 and cfg.lever and use in ("help", "guard_clear") \
                    and self.bag is not None and self.bag.mass > 0:   # w_f weighs only the lever
                d = self.predicted_clearance(state, ref)
                w_f = max(w_f, (cfg.clearance / max(d, 0.02)) ** 2)
                if use == "guard_clear":          # the guard only with the walls clear
                    use = "guard" if d >= cfg.clearance else "help"
            # the allocation's target; f_des stays the loop's, so `saturated` still reports it
            f_want = scaled_into(f_des, f_lim) if cfg.keep_direction else f_des
            if cfg.lever and use == "guard":
                force, torque = allocation.guard(f_want, tau_des, lever, f_lim, t_lim)
            else:
                w_t = cfg.w_torque * (1.0 if self.following else cfg.hold_torque_scale)
                force, torque = allocation.allocate(f_want, tau_des, lever, f_lim, t_lim,
                                                    w_f, w_t * share)
                if cfg.lever and cfg.lever_along != "free" and self.following:
                    v_ref = np.asarray(ref.velocity, float)
                    speed = float(np.linalg.norm(v_ref))
                    if speed > 0.01:
                        force, torque = allocation.keep_along(
                            force, torque, f_want, R.T @ (v_ref / speed), tau_des, lever, f_lim,
                            t_lim, brake_only=cfg.lever_along == "brake")
        else:
            force, torque = np.zeros(3), np.zeros(3)
        return Output(force=force, torque=torque, accel=R.T @ a_w, alpha=al_b,
                      position_error=e_p, position_error_integrated=np.zeros(3),
                      attitude_error=e_att, attitude_error_integrated=np.zeros(3),
                      attitude_error_mag=float(np.linalg.norm(e_att)),
                      saturated=bool(np.any(np.abs(f_des) > f_lim)
                                     or np.any(np.abs(tau_des) > t_lim)))


class GovLaw(Tracker):
    """The governed pair ControlLaw: the PD law's state machine, a GovController, and the
    progress clock (module docstring)."""

    name = "pair_gov"

    def __init__(self, flight_mode: FlightMode, mass: MassProperties,
                 config: GovConfig | None = None, hold_on_start: bool = True) -> None:
        config = (config or GovConfig()).validate()
        super().__init__(flight_mode, mass, settle_time=config.settle_time,
                         hold_on_start=hold_on_start)
        self.pd = GovController(flight_mode, mass, config)
        self.config = config
        self.progress = 0.0      # s on the segment's clock
        self.sigma = 1.0
        self._last = None
        self._t0 = 0.0
        self._fit: CorridorFit | None = None

    def observe_bag(self, bag: BagObservation | None, robot: State | None) -> None:
        self.carrying = bag is not None and bag.attached and robot is not None
        self.pd.observe(bag, robot)

    def follow(self, traj, now: float) -> None:
        super().follow(traj, now)
        self.progress, self.sigma, self._last = self.traj.start_time, 1.0, now
        self._t0 = now - self.traj.start_time

    def governor(self, state: State, ref: Reference) -> float:
        """The progress rate wanted now (1: on the clock, 0: pause)."""
        cfg = self.config
        e = rot.angle_between(state.orientation, ref.orientation)
        return min(ramp(e, cfg.att_slow, cfg.att_stop),
                   ramp(float(np.linalg.norm(state.omega)), cfg.rate_slow, cfg.rate_stop),
                   ramp(self.pd.swing_speed, cfg.swing_slow, cfg.swing_stop))

    def fit_shift(self, state: State, now: float) -> None:
        """The corridor fit's shift for this tick: decided over the plan ahead while a segment
        is followed with the bag held, returned to zero otherwise (corridor_fit)."""
        pd, cfg = self.pd, self.config
        if self._fit is None:
            keep_in, half = pd.walls()
            self._fit = CorridorFit(keep_in, half, cfg.fit, cfg.fit_horizon, cfg.fit_speed,
                                    cfg.fit_margin)
        fit, bag = self._fit, pd.bag
        if pd.following and bag is not None and bag.mass > 0:
            if fit.due(now):                  # the inputs only when a decision is due (5 Hz)
                clock = self.progress if self.config.retime else now
                route = np.array([self.traj.sample(min(clock + t, self.traj.end_time)).position
                                  for t in fit.times])
                p = np.asarray(state.position, float)
                points = pair_points(p, bag.position,
                                     rot.to_matrix(rot.normalize(bag.orientation)), bag.size)
                m_r, m_b = float(pd.mass.mass), float(bag.mass)
                centre = (m_b / (m_r + m_b)) * (np.asarray(bag.position, float) - p)
                rate = rot.to_matrix(rot.normalize(state.orientation)) @ pd.pair_rate(state)
                fit.decide(now, route, points, centre, rate)
        else:
            fit.release()
        pd.shift = fit.advance(now)

    def update(self, state: State, now: float, dt: float) -> Step:
        """One tick; while a segment is followed, the reference runs on the progress clock."""
        self.pd.following = self.state == CONTROLLING and self.traj is not None
        if self.config.fit > 0:
            self.fit_shift(state, now)
        if not (self.config.retime and self.state == CONTROLLING and self.traj is not None):
            return super().update(state, now, dt)
        traj = self.traj
        h = max(0.0, now - (self._last if self._last is not None else now))
        self._last = now
        ref_now = traj.sample(min(self.progress, traj.end_time))
        want = self.governor(state, ref_now)
        if now - self.progress > self.config.max_delay + self._t0:
            want = 1.0
        self.sigma = want if want < self.sigma else min(want, self.sigma + self.config.sigma_rate * h)
        self.progress += self.sigma * h
        if self.progress >= traj.end_time:
            self.hold = traj.final()
            self.traj = None
            self._stopping_since = now
            self._transition(STOPPING, "end of segment")
            return super().update(state, now, dt)
        r = traj.sample(self.progress)
        s = self.sigma
        ref = Reference(r.position, s * np.asarray(r.velocity), s * s * np.asarray(r.accel),
                        r.orientation, s * np.asarray(r.omega), s * s * np.asarray(r.alpha))
        return self._step(self.pd.step(state, ref, dt), ref, MODE_NOMINAL)


PARAMETERS = {**config_parameters(GovConfig()), "hold_on_start": True}


def check_params(params: dict) -> None:
    """The law's parameters (complete), checked without building it (one-line errors)."""
    GovConfig.from_params(params)
    check_hold_on_start(params)


def make_gov_law(flight_mode: FlightMode, mass: MassProperties, params: dict) -> GovLaw:
    """The governed pair law of the parameters (ValueError with one line for a bad value)."""
    params = {**PARAMETERS, **params}
    check_params(params)
    return GovLaw(flight_mode, mass, GovConfig.from_params(params),
                  hold_on_start=bool(params["hold_on_start"]))


CONTROLLER = Controller("pair_gov", make_gov_law, PARAMETERS, check_params,
                        "PD on the robot with a torque-aware attitude loop, the force's torque "
                        "through the grasp in the allocation, and a progress clock that pauses "
                        "the route while the pair is disturbed")
