"""The pair-aware tracking law: robot + carried bag controlled as one pair at 62.5 Hz.

PD on the robot's own pose (pd.py) fights itself when it carries a 10 kg bag: the pair's centre
of mass sits ~0.25 m from the robot towards the bag, so every force of the position loop turns
the pair (up to 0.08-0.1 N m, 2.5-3x the torque limits) and the attitude loop saturates against
it. This law instead
- tracks the pair's centre of mass: the reference is the robot's planned trajectory moved by the
  known bag offset (c_ref = p_ref + R_ref c, c = m_b / M d, d the bag's rest offset observed in
  the body frame), the measured centre from the robot and the observed bag (/sim/bag/state);
- tracks the attitude with a torque-aware rate limit (the wanted rate towards the reference is
  at most sqrt(2 a e) for the angular deceleration a the pair can get, so a large error is not
  turned into a spin the torque cannot brake) and the pair's inertia about its centre;
- can damp the bag's swing about the handle by following the bag's motion across the lever
  (swing_kd, swing_kp; off by default: see below);
- allocates the body wrench by allocation.allocate: the force's torque about the centre counts,
  weighted up with the attitude error (w_torque times |e| / (attitude_share x tolerance),
  between 10% and 100% of it): attitude first once the attitude is what is at stake.
Measured (a 5 N, 0.2 s push across the lever on the held bag, the law holding its pose, relative
bag-robot speed RMS over 2-5 / 10-15 s): on the constraint bag's strap grasp PD 0.064 / 0.074
m/s (the swing does not decay), these defaults 0.077 / 0.034; with swing damping on (swing_kd 1)
0.062 / 0.046, with the torque weight at 10 at the tolerance 0.044 / 0.14 (the force's torque
about a rigid-pair centre is the wrong lever for a bag that pivots: it pumps the swing). On the
old 5-anchor handle the swing damping was the best (0.025 / 0.0011).
Without a bag it is a PD with the same allocation (c = 0). PairLaw wraps it in the PD law's
state machine (tracking.Tracker): segment, stop, hold, results behave as with PD.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from astrobee import rotations as rot
from astrobee.flight_modes import FlightMode

from . import allocation
from .law import BagObservation, carried_reference, check_hold_on_start, config_parameters
from .mass import MassProperties, box_inertia
from .pd import Output, Reference, State
from .registry import Controller
from .tracking import Tracker


HELD = ("pivot", "rigid")


@dataclass
class PairConfig:
    """The pair law's parameters (also the node's ROS parameters of the same names)."""

    swing_kp: float = 0.0          # 1/s^2, pulls the bag back to its rest offset (x bag mass)
    swing_kd: float = 0.0          # 1/s, follows the bag's motion across the lever (x bag mass;
                                   # off: measured to pump the swing on the strap grasp)
    grasp: tuple = (-0.234, 0.0, -0.065)  # m, grasp point, robot body frame (the sim's gripper tip)
    held: str = "rigid"            # rigid: robot + bag one body about their centre; pivot: the
                                   # bag turns about the grasp (the robot turns alone)
    w_torque: float = 1.0          # allocation: torque-about-centre weight (force weight 1) ...
    attitude_share: float = 10.0   # ... reached at this multiple of the attitude tolerance (10%
                                   # of it at zero attitude error; see the module docstring)
    brake_share: float = 0.5       # share of the pair's angular deceleration the rate limit uses
    offset_filter: float = 0.999   # per-tick low-pass of the observed bag offset (its rest)
    centre: bool = True            # track the pair's centre (False: the robot's, ablation)
    torque_lever: bool = True      # the force's torque about the centre counts (False: ablation)
    settle_time: float = 5.0

    def validate(self) -> "PairConfig":
        """Raise ValueError (one line) for a value the law cannot run with."""
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "grasp":
                if len(v) != 3 or not all(isinstance(x, (int, float)) and math.isfinite(x)
                                          for x in v):
                    raise ValueError(f"grasp must be three finite numbers (m), got {v!r}")
                continue
            if f.name == "held":
                continue
            if f.type in ("bool", bool):
                if not isinstance(v, (bool, np.bool_)):
                    raise ValueError(f"{f.name} must be true or false, got {v!r}")
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{f.name} must be a finite number, got {v!r}")
        for name in ("swing_kp", "swing_kd", "w_torque", "attitude_share"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if self.held not in HELD:
            raise ValueError(f"held must be one of {', '.join(HELD)}, got {self.held!r}")
        if not 0 < self.brake_share <= 1:
            raise ValueError(f"brake_share must be in (0, 1], got {self.brake_share!r}")
        if not 0 <= self.offset_filter < 1:
            raise ValueError(f"offset_filter must be in [0, 1), got {self.offset_filter!r}")
        if not self.settle_time > 0:
            raise ValueError(f"settle_time must be > 0 s, got {self.settle_time!r}")
        return self

    @classmethod
    def from_params(cls, params: dict) -> "PairConfig":
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in params.items() if k in names}).validate()


@dataclass
class Pair:
    """The carried pair's figures this tick (robot body frame unless said)."""

    mass: float               # kg, robot + bag
    bag_mass: float
    offset: np.ndarray        # (3,) robot -> bag centre at rest
    lever: np.ndarray         # (3,) the force's lever: robot -> the point the pair turns about
    inertia: np.ndarray       # (3, 3) about that point
    centre: np.ndarray        # (3,) robot -> the pair's centre of mass with the bag at rest


class PairController:
    """The pair-aware wrench law (module docstring) behind the PdTracker interface the Tracker
    drives: step(state, ref, dt) -> Output, reset, set_flight_mode, set_mass."""

    def __init__(self, flight_mode: FlightMode, mass: MassProperties,
                 config: PairConfig | None = None) -> None:
        self.flight_mode = flight_mode
        self.mass = mass                      # the robot's own (the bag comes from observe)
        self.config = (config or PairConfig()).validate()
        self.bag: BagObservation | None = None
        self.rest_offset: np.ndarray | None = None
        self.bag_rotation = np.eye(3)          # bag -> robot body
        self.last_wanted = np.zeros(6)        # wanted body force, torque about the centre

    def reset(self) -> None:
        """Nothing integrates (the flight mode's integral gains are ~1e-4)."""

    def set_flight_mode(self, mode: FlightMode) -> None:
        self.flight_mode = mode

    def set_mass(self, mass: MassProperties) -> None:
        self.mass = mass

    def observe(self, bag: BagObservation | None, robot: State | None) -> None:
        """The carried bag (None: released); its body-frame offset is low-passed into the rest
        offset (the first observation sets it: the bag starts at rest)."""
        if bag is None or not bag.attached or robot is None or bag.mass <= 0:
            self.bag, self.rest_offset = None, None
            return
        offset, self.bag_rotation = bag.offset_in(robot)
        a = self.config.offset_filter
        self.rest_offset = offset if self.rest_offset is None else \
            a * self.rest_offset + (1.0 - a) * offset
        self.bag = bag

    def pair(self) -> Pair:
        """Mass, offset, lever and inertia of robot + bag (the robot alone without a bag)."""
        m_r, I_r = float(self.mass.mass), np.asarray(self.mass.inertia, float)
        if self.bag is None or self.rest_offset is None:
            return Pair(m_r, 0.0, np.zeros(3), np.zeros(3), I_r, np.zeros(3))
        m_b = float(self.bag.mass)
        M = m_r + m_b
        d = self.rest_offset
        mu = m_r * m_b / M
        if self.config.held == "pivot":
            # the bag turns about the grasp: the robot turns alone, the bag's mass pulling at the
            # grasp point (the force's torque about the robot is -(m_b/M) g x F when the bag
            # follows); the pair's centre for tracking is the robot's own
            g = np.asarray(self.config.grasp, float)
            I_p = I_r + mu * (g @ g * np.eye(3) - np.outer(g, g))
            return Pair(M, m_b, d.copy(), (m_b / M) * g, I_p, (m_b / M) * d)
        Rb = self.bag_rotation
        I_c = I_r + Rb @ box_inertia(m_b, self.bag.size) @ Rb.T \
            + mu * (d @ d * np.eye(3) - np.outer(d, d))
        return Pair(M, m_b, d.copy(), (m_b / M) * d, I_c, (m_b / M) * d)

    def step(self, state: State, ref: Reference, dt: float) -> Output:
        """The body-frame wrench for `state` tracking the robot reference `ref`."""
        fm, cfg = self.flight_mode, self.config
        q = rot.normalize(state.orientation)
        R = rot.to_matrix(q)
        w = np.asarray(state.omega, float)
        pair = self.pair()
        c = pair.centre if cfg.centre else np.zeros(3)
        # the pair's centre: measured from robot + bag, reference from the robot's plan
        w_ref = np.asarray(ref.omega, float)
        p_ref, v_ref = carried_reference(ref, c)
        p, v = np.asarray(state.position, float), np.asarray(state.velocity, float)
        swing = np.zeros(3)
        if self.bag is not None and pair.bag_mass > 0:
            pb, vb = np.asarray(self.bag.position, float), np.asarray(self.bag.velocity, float)
            swing = self._swing(R, w, state, pb, vb, pair)
            if cfg.centre and cfg.held == "pivot":     # the measured centre of mass
                gm = pair.bag_mass / pair.mass
                p, v = p + gm * (pb - p), v + gm * (vb - v)
        if cfg.centre and cfg.held == "rigid":   # the centre of the pair as held: it stays put
            p = p + R @ c                         # while the pair turns about it
            v = v + np.cross(R @ w, R @ c)
        e_p, e_v = p_ref - p, v_ref - v
        a_w = np.asarray(ref.accel, float) + fm.pos_kp * e_p + fm.vel_kd * e_v
        f_des = R.T @ (pair.mass * a_w) + swing
        # attitude: torque-aware rate limit, then the pair's inertia about its centre
        e_att = rot.attitude_error(q, ref.orientation)
        I_c = pair.inertia
        t_lim, f_lim = np.asarray(fm.max_torque, float), np.asarray(fm.max_force, float)
        lever = pair.lever if cfg.torque_lever else np.zeros(3)
        avail = t_lim + float(np.linalg.norm(lever)) * float(np.min(f_lim))
        alpha_max = cfg.brake_share * avail / np.diag(I_c)
        w_des = R.T @ w_ref + _rate_limited(e_att, fm.att_kp / fm.omega_kd, alpha_max,
                                            float(fm.hard_limit_omega))
        al_b = R.T @ np.asarray(ref.alpha, float) + fm.omega_kd * (w_des - w)
        tau_des = I_c @ al_b + np.cross(w, I_c @ w)
        self.last_wanted = np.concatenate([f_des, tau_des])
        if fm.control_enabled:
            # attitude first as the attitude error nears the tolerance; near the reference the
            # translation (walls, the bag's swing) may borrow the torque axes
            share = float(np.clip(np.linalg.norm(e_att) / (cfg.attitude_share *
                                                           fm.tolerance_att), 0.1, 1.0))
            force, torque = allocation.allocate(f_des, tau_des, lever, f_lim, t_lim,
                                                1.0, cfg.w_torque * share)
        else:
            force, torque = np.zeros(3), np.zeros(3)
        return Output(force=force, torque=torque, accel=R.T @ a_w, alpha=al_b,
                      position_error=np.asarray(ref.position, float) - state.position,
                      position_error_integrated=np.zeros(3), attitude_error=e_att,
                      attitude_error_integrated=np.zeros(3),
                      attitude_error_mag=float(np.linalg.norm(e_att)),
                      saturated=bool(np.any(np.abs(f_des) > f_lim)
                                     or np.any(np.abs(tau_des) > t_lim)))

    def _swing(self, R: np.ndarray, w: np.ndarray, state: State, pb: np.ndarray,
               vb: np.ndarray, pair: Pair) -> np.ndarray:
        """Body force that damps the bag's motion about the grasp and pulls it back to rest: the
        robot follows the bag across the lever (grasp -> bag centre): the pivot moved with the
        swing takes its energy out. Gains per kg of bag (PD on the robot's own position damps
        the swing with its velocity gain x the bag mass; this law does it explicitly)."""
        cfg = self.config
        g = np.asarray(cfg.grasp, float)
        r = R.T @ (pb - np.asarray(state.position, float)) - g          # grasp -> bag, body
        rd = R.T @ (vb - np.asarray(state.velocity, float)) - np.cross(w, g)   # vs the grasp
        n = r / max(float(np.linalg.norm(r)), 1e-9)
        e = (r + g) - pair.offset
        e = e - (e @ n) * n
        ed = rd - (rd @ n) * n
        return pair.bag_mass * (cfg.swing_kp * e + cfg.swing_kd * ed)


def _rate_limited(e: np.ndarray, k: float, alpha_max: np.ndarray, w_max: float) -> np.ndarray:
    """The rate wanted towards an attitude error e (body rotation vector): k e, at most
    sqrt(2 alpha e) per axis (the pair can still brake to rest at the reference) and w_max."""
    mag = np.abs(e)
    lim = np.minimum(np.sqrt(2.0 * alpha_max * mag), w_max)
    return np.sign(e) * np.minimum(k * mag, lim)


class PairLaw(Tracker):
    """The pair-aware ControlLaw: the PD law's state machine around a PairController."""

    name = "pair"

    def __init__(self, flight_mode: FlightMode, mass: MassProperties,
                 config: PairConfig | None = None, hold_on_start: bool = True) -> None:
        config = (config or PairConfig()).validate()
        super().__init__(flight_mode, mass, settle_time=config.settle_time,
                         hold_on_start=hold_on_start)
        self.pd = PairController(flight_mode, mass, config)
        self.config = config

    def observe_bag(self, bag: BagObservation | None, robot: State | None) -> None:
        self.carrying = bag is not None and bag.attached and robot is not None
        self.pd.observe(bag, robot)


# the pair law's parameters beyond every controller's (name -> default; one owner: PairConfig)
PARAMETERS = {**config_parameters(PairConfig()), "hold_on_start": True}


def check_params(params: dict) -> None:
    """The pair law's parameters (complete), checked without building it (one-line errors)."""
    PairConfig.from_params(params)
    check_hold_on_start(params)


def make_pair_law(flight_mode: FlightMode, mass: MassProperties, params: dict) -> PairLaw:
    """The pair law of the parameters (PARAMETERS' names; ValueError with one line for a bad
    value)."""
    params = {**PARAMETERS, **params}
    check_params(params)
    return PairLaw(flight_mode, mass, PairConfig.from_params(params),
                   hold_on_start=bool(params["hold_on_start"]))


# the registry entry (astrobee_control.registry; pyproject's astrobee.controllers group)
CONTROLLER = Controller("pair", make_pair_law, PARAMETERS, check_params,
                        "pair-aware tracking: the pair's centre and attitude, swing damping, "
                        "wrench allocation with the force's torque about the centre")


