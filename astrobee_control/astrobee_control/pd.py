"""PD(+I) trajectory tracker in the form of Astrobee's CTL: feed-forward from the reference plus
PD on position/velocity and attitude/angular velocity, output as a BODY-frame wrench.

Frames (documented contract):
- state.position, state.velocity: world frame; state.orientation [x,y,z,w] body -> world;
  state.omega: BODY frame (like the EKF's gyro-based omega; the node converts if a source
  publishes a world-frame angular velocity).
- Reference: position, velocity, accel, omega, alpha all in the WORLD frame (as in ControlState).
- Output force/torque/accel/alpha: BODY frame (as /gnc/ctl/command). position_error and its
  integral: world frame; attitude_error and its integral: body frame.

Law (parallel PD, gains per axis from the flight mode, normalised by mass/inertia):
    a_w   = a_ref + Kp e_p + Kd e_v + Ki int(e_p)          e_p = p_ref - p, e_v = v_ref - v
    F_b   = m R^T a_w
    al_b  = R^T alpha_ref + Kp_att e_att + Kd_att e_w + Ki_att int(e_att)
    tau_b = I al_b + w x I w                                e_att = rotvec(q^-1 q_ref),
                                                            e_w = R^T w_ref - w
Wrench components are clipped per body axis to the flight mode's propulsion limits; the
integrators are frozen while an axis saturates and clamped in magnitude (anti-windup).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from astrobee import rotations as rot
from astrobee.flight_modes import FlightMode

from .mass import MassProperties

# control_mode values of FamCommand (as NASA ff_msgs/ControlCommand modes)
MODE_IDLE = 0
MODE_STOP = 1
MODE_NOMINAL = 2


@dataclass
class State:
    """Measured rigid-body state (see the module docstring for frames)."""

    position: np.ndarray
    velocity: np.ndarray
    orientation: np.ndarray
    omega: np.ndarray  # body frame


@dataclass
class Reference:
    """Reference state of a trajectory at one instant (world frame)."""

    position: np.ndarray
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    accel: np.ndarray = field(default_factory=lambda: np.zeros(3))
    orientation: np.ndarray = field(default_factory=lambda: rot.IDENTITY.copy())
    omega: np.ndarray = field(default_factory=lambda: np.zeros(3))
    alpha: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def hold(cls, position: np.ndarray, orientation: np.ndarray) -> "Reference":
        """Zero-velocity reference at a pose (stopping / station keeping)."""
        return cls(np.asarray(position, float).copy(), orientation=rot.normalize(orientation))


@dataclass
class Output:
    """One control step: body-frame wrench and the FamCommand error fields."""

    force: np.ndarray
    torque: np.ndarray
    accel: np.ndarray
    alpha: np.ndarray
    position_error: np.ndarray
    position_error_integrated: np.ndarray
    attitude_error: np.ndarray
    attitude_error_integrated: np.ndarray
    attitude_error_mag: float
    saturated: bool


class PdFeedback:
    """Astrobee-style PD(+I) feedback: one wrench per state and reference; holds only the
    integrator state between steps (the PD law around it is tracking.PdLaw)."""

    def __init__(self, flight_mode: FlightMode, mass: MassProperties,
                 integral_limit_pos: float = 0.5, integral_limit_att: float = 0.5,
                 clip: bool = True) -> None:
        self.flight_mode = flight_mode
        self.mass = mass
        self.integral_limit_pos = integral_limit_pos
        self.integral_limit_att = integral_limit_att
        self.clip = clip
        self.reset()

    def reset(self) -> None:
        """Zero the integrators (new segment, flight-mode change)."""
        self._int_pos = np.zeros(3)
        self._int_att = np.zeros(3)

    def set_flight_mode(self, mode: FlightMode) -> None:
        self.flight_mode = mode

    def set_mass(self, mass: MassProperties) -> None:
        self.mass = mass

    def step(self, state: State, ref: Reference, dt: float) -> Output:
        """The body-frame wrench for `state` tracking `ref`; dt (s) advances the integrators."""
        fm = self.flight_mode
        q = rot.normalize(state.orientation)
        r = rot.to_matrix(q)
        w = np.asarray(state.omega, float)

        e_p = np.asarray(ref.position, float) - np.asarray(state.position, float)
        e_v = np.asarray(ref.velocity, float) - np.asarray(state.velocity, float)
        e_att = rot.attitude_error(q, ref.orientation)
        w_ref_b = r.T @ np.asarray(ref.omega, float)
        e_w = w_ref_b - w

        int_pos = _clamp_norm(self._int_pos + e_p * dt, self.integral_limit_pos)
        int_att = _clamp_norm(self._int_att + e_att * dt, self.integral_limit_att)

        def wrench(ip: np.ndarray, ia: np.ndarray) -> tuple[np.ndarray, ...]:
            a_w = np.asarray(ref.accel, float) + fm.pos_kp * e_p + fm.vel_kd * e_v + fm.pos_ki * ip
            a_b = r.T @ a_w
            al_b = (r.T @ np.asarray(ref.alpha, float) + fm.att_kp * e_att + fm.omega_kd * e_w
                    + fm.att_ki * ia)
            inertia = self.mass.inertia
            return a_b, al_b, self.mass.mass * a_b, inertia @ al_b + _cross(w, inertia @ w)

        a_b, al_b, force, torque = wrench(int_pos, int_att)
        saturated = False
        if self.clip and fm.control_enabled:
            f_lim, t_lim = np.asarray(fm.max_force, float), np.asarray(fm.max_torque, float)
            sat_f = bool(np.any(np.abs(force) > f_lim))
            sat_t = bool(np.any(np.abs(torque) > t_lim))
            saturated = sat_f or sat_t
            # anti-windup: do not integrate through a saturated output
            if sat_f:
                int_pos = self._int_pos
            if sat_t:
                int_att = self._int_att
            if sat_f or sat_t:
                a_b, al_b, force, torque = wrench(int_pos, int_att)
            force = np.clip(force, -f_lim, f_lim)
            torque = np.clip(torque, -t_lim, t_lim)
        if not fm.control_enabled:
            force, torque = np.zeros(3), np.zeros(3)
        self._int_pos, self._int_att = int_pos, int_att
        return Output(force=force, torque=torque, accel=a_b, alpha=al_b,
                      position_error=e_p, position_error_integrated=int_pos.copy(),
                      attitude_error=e_att, attitude_error_integrated=int_att.copy(),
                      attitude_error_mag=float(np.linalg.norm(e_att)), saturated=saturated)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _clamp_norm(v: np.ndarray, limit: float) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v * (limit / n) if n > limit else v


PdTracker = PdFeedback     # its former name (many call sites)
