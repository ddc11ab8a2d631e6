"""`pd_seed`: the PD law tuned as the seed (danielpmorton/pyastrobee) tunes it, for the paper
scenario's comparison with the project's PD (same state machine, the seed's feedback).

Figures read from the seed's code (its force/torque tracking controller and the sampling-MPC
script that builds it; read, not copied):
- world-frame PD with feed-forward: F = m a_ref - kv (v - v_ref) - kp (p - p_ref);
  tau = I_w alpha_ref + w x (I_w w) - kw (w - w_ref) - kq e_q, with I_w the inertia turned to
  the world frame and e_q twice the vector part of the quaternion error (world frame, the
  small-angle rotation vector);
- gains kp 20, kv 5, kq 1, kw 0.1; the law is told the robot's mass and inertia only (the
  carried bag is not fed forward);
- force clipped by norm to 0.849 N, torque to 0.0849 N m (docs/FACTS: a simplification).
The wrench leaves in the BODY frame like every law's and the sim clips it per axis to the flight
mode's limits; following, stopping and holding are the PD law's (tracking.PdLaw).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from astrobee import rotations as rot
from astrobee.flight_modes import FlightMode

from .law import BagObservation
from .mass import MassProperties
from .pd import Output, Reference, State
from .registry import Controller
from .tracking import PARAMETERS as PD_PARAMETERS
from .tracking import PdLaw, check_params as check_pd_params, check_settle_time

# the seed's gains and clipping (the module docstring says where each comes from)
PARAMETERS = {**PD_PARAMETERS, "kp": 20.0, "kv": 5.0, "kq": 1.0, "kw": 0.1,
              "max_force": 0.849, "max_torque": 0.0849}
GAINS = ("kp", "kv", "kq", "kw", "max_force", "max_torque")


def _clip_norm(v: np.ndarray, limit: float) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v * (limit / n) if n > limit > 0 else v


class SeedFeedback:
    """The seed's PD feedback with the PdFeedback interface (step / reset / set_mass /
    set_flight_mode) so PdLaw's state machine drives it."""

    def __init__(self, flight_mode: FlightMode, mass: MassProperties, kp: float, kv: float,
                 kq: float, kw: float, max_force: float, max_torque: float) -> None:
        self.flight_mode = flight_mode
        self.mass = mass
        self.kp, self.kv, self.kq, self.kw = kp, kv, kq, kw
        self.max_force, self.max_torque = max_force, max_torque

    def reset(self) -> None:
        """No integrator to clear."""

    def set_flight_mode(self, mode: FlightMode) -> None:
        self.flight_mode = mode

    def set_mass(self, mass: MassProperties) -> None:
        self.mass = mass

    def step(self, state: State, ref: Reference, dt: float) -> Output:  # noqa: ARG002
        """The body-frame wrench for `state` tracking `ref` (see the module docstring)."""
        q = rot.normalize(state.orientation)
        r = rot.to_matrix(q)
        w = r @ np.asarray(state.omega, float)                  # world frame
        e_p = np.asarray(ref.position, float) - np.asarray(state.position, float)
        e_v = np.asarray(ref.velocity, float) - np.asarray(state.velocity, float)
        q_ref = rot.normalize(ref.orientation)
        q_e = rot.multiply(q, rot.conjugate(q_ref))
        e_q = 2.0 * np.asarray(q_e[:3]) * (1.0 if q_e[3] >= 0 else -1.0)   # q w.r.t. q_ref
        inertia_w = r @ self.mass.inertia @ r.T
        force_w = self.mass.mass * np.asarray(ref.accel, float) + self.kv * e_v + self.kp * e_p
        torque_w = (inertia_w @ np.asarray(ref.alpha, float) + np.cross(w, inertia_w @ w)
                    - self.kw * (w - np.asarray(ref.omega, float)) - self.kq * e_q)
        clipped_f, clipped_t = _clip_norm(force_w, self.max_force), _clip_norm(torque_w, self.max_torque)
        saturated = bool(clipped_f is not force_w or clipped_t is not torque_w)
        if not self.flight_mode.control_enabled:
            clipped_f, clipped_t = np.zeros(3), np.zeros(3)
        force, torque = r.T @ clipped_f, r.T @ clipped_t
        e_att = rot.attitude_error(q, q_ref)
        return Output(force=force, torque=torque, accel=force / self.mass.mass,
                      alpha=np.linalg.solve(self.mass.inertia, torque),
                      position_error=e_p, position_error_integrated=np.zeros(3),
                      attitude_error=e_att, attitude_error_integrated=np.zeros(3),
                      attitude_error_mag=float(np.linalg.norm(e_att)), saturated=saturated)


class SeedPdLaw(PdLaw):
    """The PD law's state machine around the seed's feedback; told the robot's mass only."""

    name = "pd_seed"

    def __init__(self, flight_mode: FlightMode, mass: MassProperties, params: dict) -> None:
        super().__init__(flight_mode, mass, settle_time=check_settle_time(params["settle_time"]),
                         hold_on_start=bool(params["hold_on_start"]))
        self.pd = SeedFeedback(flight_mode, mass, *(float(params[k]) for k in GAINS))

    def observe_bag(self, bag: BagObservation | None, robot: State | None) -> None:
        """The bag is seen (carrying) but not fed forward: the seed tells its PD the robot's
        mass only."""
        self.carrying = bag is not None and bag.attached and robot is not None


def check_params(params: dict[str, Any]) -> None:
    """pd_seed's parameters (complete): the PD law's, and gains / limits finite and >= 0."""
    check_pd_params(params)
    for k in GAINS:
        v = params[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (v >= 0 and np.isfinite(v)):
            raise ValueError(f"{k} must be a finite number >= 0, got {v!r}")


def make_law(flight_mode: FlightMode, mass: MassProperties, params: dict) -> SeedPdLaw:
    """The seed-tuned PD law of the parameters (PARAMETERS' names; ValueError, one line)."""
    params = {**PARAMETERS, **params}
    check_params(params)
    return SeedPdLaw(flight_mode, mass, params)


CONTROLLER = Controller("pd_seed", make_law, PARAMETERS, check_params,
                        "PD tuned as the seed (pyastrobee) tunes it: world-frame gains "
                        "kp 20 kv 5 kq 1 kw 0.1, robot mass only, norm clipping 0.849 N / "
                        "0.0849 N m")
