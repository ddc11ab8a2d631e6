"""Rollout model A: a closed-form reduced-order model of Astrobee carrying a cargo bag.

The robot is a translational rigid body of mass m_r; the bag is a point mass m_b tied to the
robot's body frame by a linear spring-damper: the bag centre rests at `rest_offset` (body
frame) and is pulled back by per-body-axis stiffness k and damping c. This is the paper's
"closed-form reduced-order model integrated without a simulator in the loop" (its future work):
the swing and lag of the bag behind an accelerating robot, nothing of the bag's shape.

Attitude is not integrated: the robot's attitude loop is fast beside the position loop, so the
rollout takes the robot's orientation to be the reference's (one rotation per time step, shared
by every candidate). The PD law in the rollout is pd.py's position part (feed-forward
acceleration + Kp e_p + Kd e_v, times the feed-forward mass, clipped per body axis to the flight
mode's force limits), without the tiny integral term.

Integration: semi-implicit with the spring-damper solved implicitly per body axis (backward
Euler of the relative coordinate, exact centre-of-mass update), so a stiff handle (a rigid
ball-joint bag identifies at k ~ 1e3 N/m) stays stable at a 40 ms rollout step. Everything is
vectorised over the N candidates: one step is a dozen numpy operations on (N, 3) arrays.

`simulate_bag` is the same spring-damper driven by a recorded (kinematic) robot motion: what the
system identification (sysid.py) fits and reports its error with.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class HandleParams:
    """The bag's handle as a spring-damper (body-frame axes of the robot)."""

    stiffness: np.ndarray     # (3,) N/m
    damping: np.ndarray       # (3,) N s/m
    rest_offset: np.ndarray   # (3,) m, bag centre at rest in the robot body frame
    drag: float = 0.0         # N s/m, damping of the bag's absolute velocity (the FEM bag's
                              # node damping acts like this: it trails a moving robot)

    def __post_init__(self) -> None:
        for name in ("stiffness", "damping", "rest_offset"):
            v = np.broadcast_to(np.asarray(getattr(self, name), float), (3,)).copy()
            if not np.all(np.isfinite(v)):
                raise ValueError(f"handle {name} must be finite")
            object.__setattr__(self, name, v)
        object.__setattr__(self, "drag", float(self.drag))
        if np.any(self.stiffness < 0) or np.any(self.damping < 0) or not self.drag >= 0:
            raise ValueError("handle stiffness, damping and drag must be >= 0")

    @classmethod
    def from_dict(cls, d: dict) -> "HandleParams":
        return cls(d["stiffness"], d["damping"], d.get("rest_offset", [0.0, 0.0, 0.0]),
                   float(d.get("drag", 0.0)))

    def to_dict(self) -> dict:
        r = lambda v: [round(float(x), 5) for x in v]  # noqa: E731
        return {"stiffness": r(self.stiffness), "damping": r(self.damping),
                "rest_offset": r(self.rest_offset), "drag": round(self.drag, 5)}


@dataclass
class RolloutStart:
    """The state a rollout starts from (world frame) and the masses involved."""

    robot_position: np.ndarray
    robot_velocity: np.ndarray
    robot_mass: float                       # kg, the robot alone
    ff_mass: float                          # kg, the mass the PD law's feed-forward assumes
    bag_position: np.ndarray | None = None  # None: no bag carried
    bag_velocity: np.ndarray | None = None
    bag_mass: float = 0.0
    bag_size: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rest_offset: np.ndarray | None = None   # body frame; None: the handle params' own
    bag_rotation: np.ndarray = field(default_factory=lambda: np.eye(3))  # bag -> robot body

    @property
    def carrying(self) -> bool:
        return self.bag_position is not None and self.bag_mass > 0


@dataclass
class CandidateReferences:
    """N candidate references on a common grid of M steps of dt seconds (world frame);
    `rotation` (M, 3, 3) is the robot's body -> world rotation at each step (shared)."""

    position: np.ndarray   # (N, M, 3)
    velocity: np.ndarray   # (N, M, 3)
    accel: np.ndarray      # (N, M, 3)
    rotation: np.ndarray   # (M, 3, 3)
    dt: float


@dataclass
class Gains:
    """The position part of the PD law (flight-mode gains and body-axis force limits)."""

    kp: np.ndarray         # (3,) or scalar, 1/s^2
    kd: np.ndarray         # (3,) or scalar, 1/s
    max_force: np.ndarray  # (3,) N, body axes

    @classmethod
    def from_flight_mode(cls, fm) -> "Gains":
        return cls(np.asarray(fm.pos_kp, float), np.asarray(fm.vel_kd, float),
                   np.asarray(fm.max_force, float))


@dataclass
class Rollouts:
    """Rolled-out states after each of the M steps (index k is time (k+1) dt), world frame."""

    robot_position: np.ndarray  # (N, M, 3)
    robot_velocity: np.ndarray
    bag_position: np.ndarray | None
    bag_velocity: np.ndarray | None
    force: np.ndarray           # (N, M, 3) world-frame force the PD law applied at step k


class RolloutModel(Protocol):
    """What the MPC needs of a model: roll N candidate references out with the PD law."""

    name: str

    def rollout(self, start: RolloutStart, refs: CandidateReferences, gains: Gains) -> Rollouts: ...


class ReducedModel:
    """Rollout model A (see the module docstring), vectorised over candidates. `handles`
    (bag model -> parameters) lets `select_bag` switch to the observed bag model's."""

    name = "reduced"

    def __init__(self, handle: HandleParams, handles: dict[str, HandleParams] | None = None) -> None:
        self.handle = handle
        self.handles = dict(handles or {})

    def select_bag(self, bag_model: str) -> None:
        """Use the identified handle of `bag_model` when there is one."""
        if bag_model in self.handles:
            self.handle = self.handles[bag_model]

    def rollout(self, start: RolloutStart, refs: CandidateReferences, gains: Gains) -> Rollouts:
        """Roll every candidate reference out with the PD law on robot + spring-damper bag."""
        n, m = refs.position.shape[:2]
        dt = float(refs.dt)
        kp, kd = np.asarray(gains.kp, float), np.asarray(gains.kd, float)
        fmax = np.asarray(gains.max_force, float)
        m_r, ff = float(start.robot_mass), float(start.ff_mass)
        xr = np.broadcast_to(np.asarray(start.robot_position, float), (n, 3)).copy()
        vr = np.broadcast_to(np.asarray(start.robot_velocity, float), (n, 3)).copy()
        out_xr = np.empty((n, m, 3))
        out_vr = np.empty((n, m, 3))
        out_f = np.empty((n, m, 3))
        carrying = start.carrying
        if carrying:
            m_b = float(start.bag_mass)
            mt = m_r + m_b
            mu = m_r * m_b / mt
            k, c, beta = self.handle.stiffness, self.handle.damping, self.handle.drag
            d = self.handle.rest_offset if start.rest_offset is None else \
                np.asarray(start.rest_offset, float)
            denom = 1.0 + dt * c / mu + dt * dt * k / mu
            xb = np.broadcast_to(np.asarray(start.bag_position, float), (n, 3)).copy()
            vb = np.broadcast_to(np.asarray(start.bag_velocity, float), (n, 3)).copy()
            X = (m_r * xr + m_b * xb) / mt          # centre of mass
            V = (m_r * vr + m_b * vb) / mt
            u = xb - xr                              # robot -> bag
            ud = vb - vr
            out_xb = np.empty((n, m, 3))
            out_vb = np.empty((n, m, 3))
        for i in range(m):
            R = refs.rotation[i]
            a_w = refs.accel[:, i] + kp * (refs.position[:, i] - xr) + kd * (refs.velocity[:, i] - vr)
            f_b = np.clip(ff * (a_w @ R), -fmax, fmax)
            F = f_b @ R.T
            out_f[:, i] = F
            if carrying:
                r_b = (u @ R) - d                    # spring stretch, body frame
                rd_b = ud @ R
                drag_b = (beta * dt / m_b) * ((V + (m_r / mt) * ud) @ R) if beta else 0.0
                rd_b = (rd_b - dt * (k * r_b / mu + f_b / m_r) - drag_b) / denom
                if beta:
                    F = F - beta * (V + (m_r / mt) * ud)
                r_b = r_b + dt * rd_b
                u = (r_b + d) @ R.T
                ud = rd_b @ R.T
                V = V + dt * F / mt                  # F: PD force (+ bag drag)
                X = X + dt * V
                xr = X - (m_b / mt) * u
                vr = V - (m_b / mt) * ud
                out_xb[:, i] = X + (m_r / mt) * u
                out_vb[:, i] = V + (m_r / mt) * ud
            else:
                vr = vr + dt * F / m_r
                xr = xr + dt * vr
            out_xr[:, i] = xr
            out_vr[:, i] = vr
        if not carrying:
            return Rollouts(out_xr, out_vr, None, None, out_f)
        return Rollouts(out_xr, out_vr, out_xb, out_vb, out_f)


def simulate_bag(handle: HandleParams, bag_mass: float, t: np.ndarray, robot_position: np.ndarray,
                 robot_velocity: np.ndarray, robot_rotation: np.ndarray, bag_position0: np.ndarray,
                 bag_velocity0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bag's motion (positions, velocities (T, 3)) when the robot follows a recorded motion
    exactly (positions/velocities (T, 3), body -> world rotations (T, 3, 3) at times t (T,)):
    the spring-damper alone, integrated implicitly from the recorded first bag state."""
    k, c, d, beta = handle.stiffness, handle.damping, handle.rest_offset, handle.drag
    m_b = float(bag_mass)
    xb = np.asarray(bag_position0, float).copy()
    vb = np.asarray(bag_velocity0, float).copy()
    T = len(t)
    out_x = np.empty((T, 3))
    out_v = np.empty((T, 3))
    out_x[0], out_v[0] = xb, vb
    for i in range(1, T):
        dt = float(t[i] - t[i - 1])
        R = robot_rotation[i]
        # body-frame components at the new step:
        #   m (y - vb) = dt (-k (xb + dt y - xr - R d) - c (y - vr) - beta y)
        rel = (xb - robot_position[i]) @ R - d
        vb_b = vb @ R
        vr_b = robot_velocity[i] @ R
        y = (m_b * vb_b - dt * k * rel + dt * c * vr_b) / (m_b + dt * (c + beta) + dt * dt * k)
        vb = y @ R.T
        xb = xb + dt * vb
        out_x[i], out_v[i] = xb, vb
    return out_x, out_v


def identified_handles() -> dict[str, HandleParams]:
    """Handle parameters per bag model from config/reduced_models.yaml (bench/sysid_bag.py)."""
    from astrobee import config
    try:
        data = config.load_yaml("reduced_models.yaml")
    except config.ConfigError:
        return {}
    return {name: HandleParams.from_dict(d) for name, d in (data.get("handles") or {}).items()}

