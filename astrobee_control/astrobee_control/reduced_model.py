"""Rollout model A: a closed-form reduced-order model of Astrobee carrying a cargo bag.

Three kinds of handle, chosen per bag model in config/reduced_models.yaml (bench/sysid_bag.py):
- RigidBodyParams (`kind: rigid_body`, the FEM bag's): robot + bag one rigid body. The PD force
  acts at the robot's centre, 0.25 m off the pair's centre of mass, and Astrobee's torque limits
  (0.02-0.07 N m) are an order below the torque that makes, so the pair turns (measured on the
  fast FEM bag, 412 nodes: up to 109 deg during the identification moves) and the body-frame
  force limits turn with it. The rollout integrates the attitude (the PD law's attitude part,
  clipped) every ATTITUDE_STEP with the force's torque about the compound centre; the bag sits
  rigidly at its observed offset and its corners turn with the pair (Rollouts.bag_turn).
- HandleParams (no kind): the bag a point mass on a body-frame spring-damper + drag, the robot's
  attitude taken from the reference. Kept for the constraint/rigid bags.
- PendulumParams (`kind: pendulum`): the bag a rigid box swinging about the grasp point on a
  rotational spring-damper, attitude from the reference.
Decision (numbers of bench/sysid_bag.py, fast FEM at 412 nodes, held-out motion): the bag's
own swing relative to the robot is small (9.5 mm RMS); driven by the recorded robot motion the
spring explains none of it (11.1 mm), the pendulum little (10.5 mm), the rigid offset as much
(10.1 mm). What the MPC relies on, 5 s closed-loop rollouts from the recorded state: bag centre
RMS 55.3 mm (max 177) for the rigid body against 188.5 mm (spring fitted on the fast FEM) and
245.1 mm (spring fitted on Bullet's FEM, 250 nodes); robot 9.2 mm against 373/90 mm. So the
turning pair is what was missing; the swing about the handle is not worth its cost.

The PD law in the rollout is pd.py's (feed-forward + Kp e + Kd e_v, times the told mass/inertia,
clipped per body axis), without the small integral terms. Everything is vectorised over the N
candidates: one step is a dozen numpy operations on (N, 3) / (N, 3, 3) arrays.

`simulate_bag` / `simulate_pendulum` drive the spring / pendulum by a recorded (kinematic) robot
motion: what the system identification (sysid.py) fits.
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


@dataclass(frozen=True)
class PendulumParams:
    """The bag as a rigid box swinging about its grasp point (a spherical joint on the robot)
    held by a rotational spring-damper (robot body-frame axes). The bag centre rests at
    `rest_offset`, `lever` (hinge -> bag centre) from the hinge."""

    rot_stiffness: np.ndarray  # (3,) N m/rad
    rot_damping: np.ndarray    # (3,) N m s/rad
    rest_offset: np.ndarray    # (3,) m, robot -> bag centre at rest, robot body frame
    lever: np.ndarray          # (3,) m, hinge -> bag centre at rest, robot body frame
    inertia: np.ndarray        # (3,) kg m^2, the bag's inertia about its centre (body axes)
    kind = "pendulum"

    def __post_init__(self) -> None:
        for name in ("rot_stiffness", "rot_damping", "rest_offset", "lever", "inertia"):
            v = np.broadcast_to(np.asarray(getattr(self, name), float), (3,)).copy()
            if not np.all(np.isfinite(v)):
                raise ValueError(f"pendulum {name} must be finite")
            object.__setattr__(self, name, v)
        if np.any(self.rot_stiffness < 0) or np.any(self.rot_damping < 0) or \
                np.any(self.inertia <= 0) or not np.linalg.norm(self.lever) > 0:
            raise ValueError("pendulum stiffness, damping >= 0, inertia > 0, lever non-zero")

    @classmethod
    def from_dict(cls, d: dict) -> "PendulumParams":
        return cls(d["rot_stiffness"], d["rot_damping"], d["rest_offset"], d["lever"],
                   d["inertia"])

    def to_dict(self) -> dict:
        r = lambda v: [round(float(x), 5) for x in v]  # noqa: E731
        return {"kind": self.kind, "rot_stiffness": r(self.rot_stiffness),
                "rot_damping": r(self.rot_damping), "rest_offset": r(self.rest_offset),
                "lever": r(self.lever), "inertia": r(self.inertia)}

    def step_matrices(self, dt: float, coupling: float) -> tuple[np.ndarray, np.ndarray]:
        """(J, A): the effective inertia about the bag centre J = I + coupling * (|l|^2 1 - l l^T)
        (coupling: the bag mass for a robot that follows its reference exactly, the reduced
        mass robot-bag when the robot is free) and A = (J + dt C + dt^2 K)^-1."""
        lv = self.lever
        J = np.diag(self.inertia) + coupling * (lv @ lv * np.eye(3) - np.outer(lv, lv))
        A = np.linalg.inv(J + dt * np.diag(self.rot_damping) + dt * dt * np.diag(self.rot_stiffness))
        return J, A


ATTITUDE_STEP = 0.2   # s, the turning rollout's attitude step (its dynamics are slow: torque-limited)


@dataclass(frozen=True)
class RigidBodyParams:
    """The bag held rigidly at `rest_offset` (robot body frame), robot + bag turning as one
    torque-limited rigid body (ReducedModel's attitude rollout)."""

    rest_offset: np.ndarray  # (3,) m
    kind = "rigid_body"

    def __post_init__(self) -> None:
        v = np.broadcast_to(np.asarray(self.rest_offset, float), (3,)).copy()
        if not np.all(np.isfinite(v)):
            raise ValueError("rigid_body rest_offset must be finite")
        object.__setattr__(self, "rest_offset", v)

    @classmethod
    def from_dict(cls, d: dict) -> "RigidBodyParams":
        return cls(d["rest_offset"])

    def to_dict(self) -> dict:
        return {"kind": self.kind, "rest_offset": [round(float(x), 5) for x in self.rest_offset]}


def rotate_by(theta: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v (..., 3) by rotation vectors theta (..., 3) (Rodrigues, batched)."""
    ang = np.linalg.norm(theta, axis=-1, keepdims=True)
    k = theta / np.maximum(ang, 1e-12)
    c, s = np.cos(ang), np.sin(ang)
    return v * c + np.cross(k, v) * s + k * (np.sum(k * v, -1, keepdims=True) * (1.0 - c))


def swing_from_offset(lever: np.ndarray, rest_offset: np.ndarray, offset: np.ndarray,
                      rel_velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pendulum's small-angle swing (rotation vector, rate; body frame) that puts the bag
    centre at `offset` moving at `rel_velocity` (body frame, relative to the robot)."""
    L2 = float(lever @ lever)
    return np.cross(lever, offset - rest_offset) / L2, np.cross(lever, rel_velocity) / L2


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
    robot_orientation: np.ndarray | None = None  # [x,y,z,w] body -> world; None: the reference's
    robot_omega: np.ndarray | None = None        # rad/s, body frame; None: zero
    robot_inertia: np.ndarray | None = None      # 3x3 kg m^2, the robot alone; None: Astrobee's
    ff_inertia: np.ndarray | None = None         # 3x3, what the PD law's attitude part assumes

    @property
    def carrying(self) -> bool:
        return self.bag_position is not None and self.bag_mass > 0


@dataclass
class CandidateReferences:
    """N candidate references on a common grid of M steps of dt seconds (world frame);
    `rotation` (M, 3, 3) is the robot's body -> world rotation at each step (shared), or
    (N, M, 3, 3) one per candidate (the turning model only: ReducedModel.turns), with `omega`
    (N, M, 3) the candidates' world-frame reference rates (None: zero)."""

    position: np.ndarray   # (N, M, 3)
    velocity: np.ndarray   # (N, M, 3)
    accel: np.ndarray      # (N, M, 3)
    rotation: np.ndarray   # (M, 3, 3) or (N, M, 3, 3)
    dt: float
    omega: np.ndarray | None = None   # (N, M, 3) rad/s, world frame
    alpha: np.ndarray | None = None   # (N, M, 3) rad/s^2, world frame (feed-forward)


@dataclass
class Gains:
    """The position part of the PD law (flight-mode gains and body-axis force limits)."""

    kp: np.ndarray         # (3,) or scalar, 1/s^2
    kd: np.ndarray         # (3,) or scalar, 1/s
    max_force: np.ndarray  # (3,) N, body axes
    att_kp: np.ndarray = field(default_factory=lambda: np.full(3, 4.0))    # 1/s^2
    omega_kd: np.ndarray = field(default_factory=lambda: np.full(3, 3.2))  # 1/s
    max_torque: np.ndarray = field(default_factory=lambda: np.full(3, 0.0452))  # N m, body axes

    @classmethod
    def from_flight_mode(cls, fm) -> "Gains":
        return cls(np.asarray(fm.pos_kp, float), np.asarray(fm.vel_kd, float),
                   np.asarray(fm.max_force, float), np.asarray(fm.att_kp, float),
                   np.asarray(fm.omega_kd, float), np.asarray(fm.max_torque, float))


@dataclass
class Rollouts:
    """Rolled-out states after each of the M steps (index k is time (k+1) dt), world frame."""

    robot_position: np.ndarray  # (N, M, 3)
    robot_velocity: np.ndarray
    bag_position: np.ndarray | None
    bag_velocity: np.ndarray | None
    force: np.ndarray           # (N, M, 3) world-frame force the PD law applied at step k
    bag_turn: np.ndarray | None = None  # (N, M, 3) the robot's (and rigidly held bag's)
                                        # rotation since the start: rotation vector in the
                                        # start's body frame; None: attitude follows the reference
    rotation: np.ndarray | None = None  # (N, M, 3, 3) the robot's body -> world rotation
    omega: np.ndarray | None = None     # (N, M, 3) rad/s, its body-frame rate
    inertia: np.ndarray | None = None   # (3, 3) robot + bag about their centre of mass, body


class RolloutModel(Protocol):
    """What the MPC needs of a model: roll N candidate references out with the PD law."""

    name: str

    def rollout(self, start: RolloutStart, refs: CandidateReferences, gains: Gains) -> Rollouts: ...


class ReducedModel:
    """Rollout model A (see the module docstring), vectorised over candidates. `handles`
    (bag model -> parameters) lets `select_bag` switch to the observed bag model's."""

    name = "reduced"

    def __init__(self, handle: "HandleParams | PendulumParams",
                 handles: "dict[str, HandleParams | PendulumParams] | None" = None) -> None:
        self.handle = handle
        self.handles = dict(handles or {})

    def turns(self, start: RolloutStart) -> bool:
        """True when this rollout integrates the attitude (per-candidate rotations allowed)."""
        return isinstance(self.handle, RigidBodyParams) and start.carrying

    def select_bag(self, bag_model: str) -> None:
        """Use the identified handle of `bag_model` when there is one."""
        if bag_model in self.handles:
            self.handle = self.handles[bag_model]

    def rollout(self, start: RolloutStart, refs: CandidateReferences, gains: Gains) -> Rollouts:
        """Roll every candidate reference out with the PD law on robot + bag (the handle's
        kind: a pendulum or a point mass on a spring-damper)."""
        if isinstance(self.handle, PendulumParams) and start.carrying:
            return self._rollout_pendulum(start, refs, gains)
        if isinstance(self.handle, RigidBodyParams) and start.carrying:
            return self._rollout_turning(start, refs, gains)
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


    def _rollout_pendulum(self, start: RolloutStart, refs: CandidateReferences,
                          gains: Gains) -> Rollouts:
        """The pendulum bag (PendulumParams) on a free robot: the centre of mass moves with the
        PD force alone; the swing obeys (I + mu P) w' = -K th - C w - (m_b/M) l x F (body
        frame, P = |l|^2 1 - l l^T), integrated implicitly in (K, C); bag centre placed by
        rotating the lever exactly (Rodrigues)."""
        h = self.handle
        n, m = refs.position.shape[:2]
        dt = float(refs.dt)
        kp, kd = np.asarray(gains.kp, float), np.asarray(gains.kd, float)
        fmax = np.asarray(gains.max_force, float)
        m_r, ff, m_b = float(start.robot_mass), float(start.ff_mass), float(start.bag_mass)
        mt = m_r + m_b
        g, gr = m_b / mt, m_r / mt
        d = h.rest_offset if start.rest_offset is None else np.asarray(start.rest_offset, float)
        lv = h.lever
        hinge = d - lv
        J, A = h.step_matrices(dt, m_r * m_b / mt)
        JA = J @ A.T
        KA = (dt * h.rot_stiffness)[:, None] * A.T
        xr = np.broadcast_to(np.asarray(start.robot_position, float), (n, 3)).copy()
        vr = np.broadcast_to(np.asarray(start.robot_velocity, float), (n, 3)).copy()
        xb = np.broadcast_to(np.asarray(start.bag_position, float), (n, 3))
        vb = np.broadcast_to(np.asarray(start.bag_velocity, float), (n, 3))
        R0 = refs.rotation[0]
        th0, om = swing_from_offset(lv, d, (xb - xr) @ R0, (vb - vr) @ R0)
        th = th0.copy()
        X = g * xb + gr * xr
        V = g * vb + gr * vr
        out = {k: np.empty((n, m, 3)) for k in ("xr", "vr", "xb", "vb", "f")}
        for i in range(m):
            R = refs.rotation[i]
            a_w = refs.accel[:, i] + kp * (refs.position[:, i] - xr) + kd * (refs.velocity[:, i] - vr)
            f_b = np.clip(ff * (a_w @ R), -fmax, fmax)
            F = f_b @ R.T
            om = om @ JA - th @ KA - (dt * g) * (np.cross(lv, f_b) @ A.T)
            th = th + dt * om
            rl = rotate_by(th, lv)
            u = (hinge + rl) @ R.T
            ud = np.cross(om, rl) @ R.T
            V = V + (dt / mt) * F
            X = X + dt * V
            xr, vr = X - g * u, V - g * ud
            out["xr"][:, i], out["vr"][:, i], out["f"][:, i] = xr, vr, F
            out["xb"][:, i], out["vb"][:, i] = X + gr * u, V + gr * ud
        return Rollouts(out["xr"], out["vr"], out["xb"], out["vb"], out["f"])


    def _rollout_turning(self, start: RolloutStart, refs: CandidateReferences,
                         gains: Gains) -> Rollouts:
        """Robot + bag as one rigid body with attitude dynamics: the PD force acts at the
        robot's centre, off the compound's centre of mass, so it turns the pair; the PD law's
        attitude part (clipped to the small torque limits) turns it back. The body-frame force
        limits then rotate with the robot. Per candidate: rotation (N, 3, 3), rate (N, 3)."""
        n, m = refs.position.shape[:2]
        dt = float(refs.dt)
        kp, kd = np.asarray(gains.kp, float), np.asarray(gains.kd, float)
        fmax = np.asarray(gains.max_force, float)
        akp, akd = np.asarray(gains.att_kp, float), np.asarray(gains.omega_kd, float)
        tmax = np.asarray(gains.max_torque, float)
        m_r, ff, m_b = float(start.robot_mass), float(start.ff_mass), float(start.bag_mass)
        mt = m_r + m_b
        d = self.handle.rest_offset if start.rest_offset is None else \
            np.asarray(start.rest_offset, float)
        I_c, c = compound_inertia(start, d)
        I_inv = np.linalg.inv(I_c)
        I_ff = I_c if start.ff_inertia is None else np.asarray(start.ff_inertia, float)
        per_candidate = refs.rotation.ndim == 4
        R_ref0 = refs.rotation[:, 0] if per_candidate else refs.rotation[0]
        R = np.broadcast_to(R_ref0 if start.robot_orientation is None else
                            _quat_matrix(start.robot_orientation), (n, 3, 3)).copy()
        w = np.broadcast_to(np.zeros(3) if start.robot_omega is None else
                            np.asarray(start.robot_omega, float), (n, 3)).copy()
        dc = d - c
        R0T = R[0].T.copy()
        sub = max(1, int(round(ATTITUDE_STEP / dt)))       # rollout steps per attitude step
        dta = sub * dt
        x0 = np.asarray(start.robot_position, float)
        v0 = np.asarray(start.robot_velocity, float)
        X = np.broadcast_to(x0 + R[0] @ c, (n, 3)).copy()
        V = np.broadcast_to(v0 + R[0] @ np.cross(w[0], c), (n, 3)).copy()
        rc, rwc = R @ c, (R @ np.cross(w, c)[:, :, None])[:, :, 0]
        xr, vr = X - rc, V - rwc
        out_X, out_V, out_f = (np.empty((n, m, 3)) for _ in range(3))
        n_att = -(-m // sub)
        Rs = np.empty((n, n_att + 1, 3, 3))    # attitude during each attitude step (and after)
        Ws = np.empty((n, n_att + 1, 3))
        Rs[:, 0], Ws[:, 0] = R, w
        fsum = np.zeros((n, 3))
        for i in range(m):
            a_w = refs.accel[:, i] + kp * (refs.position[:, i] - xr) + kd * (refs.velocity[:, i] - vr)
            f_b = np.clip(ff * (a_w[:, None, :] @ R)[:, 0], -fmax, fmax)
            F = (R @ f_b[:, :, None])[:, :, 0]
            fsum += f_b
            V = V + (dt / mt) * F
            X = X + dt * V
            out_X[:, i], out_V[:, i], out_f[:, i] = X, V, F
            if i % sub == sub - 1 or i == m - 1:
                # attitude step: the PD law's torque (clipped) and the force's torque about the
                # compound centre (the force averaged over the step), semi-implicit Euler
                Rref = refs.rotation[:, i] if per_candidate else refs.rotation[i]
                e = _log_so3(R.transpose(0, 2, 1) @ Rref)
                e_w = -w if refs.omega is None else \
                    (R.transpose(0, 2, 1) @ refs.omega[:, i, :, None])[:, :, 0] - w
                al = akp * e + akd * e_w
                if refs.alpha is not None:
                    al = al + (R.transpose(0, 2, 1) @ refs.alpha[:, i, :, None])[:, :, 0]
                tq = np.clip(al @ I_ff.T, -tmax, tmax)
                w = w + dta * ((tq - np.cross(c, fsum / (i % sub + 1))) @ I_inv.T)
                R = R @ _exp_so3(dta * w)
                fsum[:] = 0.0
                Rs[:, i // sub + 1], Ws[:, i // sub + 1] = R, w
                rc, rwc = R @ c, (R @ np.cross(w, c)[:, :, None])[:, :, 0]
            xr, vr = X - rc, V - rwc
        # positions from the centre of mass and the (piecewise constant) attitude
        Rk = np.repeat(Rs[:, :n_att], sub, axis=1)[:, :m]
        Wk = np.repeat(Ws[:, :n_att], sub, axis=1)[:, :m]
        arm_r = Rk @ (-c)
        arm_b = Rk @ dc
        vel_r = (Rk @ np.cross(Wk, -c)[..., None])[..., 0]
        vel_b = (Rk @ np.cross(Wk, dc)[..., None])[..., 0]
        turn = np.repeat(_log_so3((R0T @ Rs[:, :n_att]).reshape(-1, 3, 3)).reshape(n, n_att, 3),
                         sub, axis=1)[:, :m]
        return Rollouts(out_X + arm_r, out_V + vel_r, out_X + arm_b, out_V + vel_b, out_f, turn,
                        Rk, Wk, I_c)


def compound_inertia(start: RolloutStart, rest_offset: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(inertia (3, 3) of robot + rigidly held bag about their centre of mass, that centre
    (3,)), both in the robot's body frame, the bag's centre at `rest_offset`."""
    from .mass import box_inertia, robot as robot_mass
    m_r, m_b = float(start.robot_mass), float(start.bag_mass)
    mt = m_r + m_b
    d = np.asarray(rest_offset, float)
    Rb = np.asarray(start.bag_rotation, float)
    I_r = robot_mass().inertia if start.robot_inertia is None else start.robot_inertia
    I_c = (np.asarray(I_r, float) + Rb @ box_inertia(m_b, start.bag_size) @ Rb.T
           + (m_r * m_b / mt) * (d @ d * np.eye(3) - np.outer(d, d)))
    return I_c, (m_b / mt) * d


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    from astrobee import rotations as rot
    return rot.to_matrix(np.asarray(q, float))


def _exp_so3(v: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) of rotation vectors v (N, 3) (Rodrigues)."""
    ang = np.sqrt(np.sum(v * v, -1))[:, None, None]
    K = (v @ _SKEW).reshape(-1, 3, 3)
    safe = np.maximum(ang, 1e-12)
    return np.eye(3) + (np.sin(ang) / safe) * K + ((1.0 - np.cos(ang)) / (safe * safe)) * (K @ K)


# v @ _SKEW is the cross-product matrix [v]x, flattened row-major
_SKEW = np.array([[0, 0, 0, 0, 0, -1, 0, 1, 0], [0, 0, 1, 0, 0, 0, -1, 0, 0],
                  [0, -1, 0, 1, 0, 0, 0, 0, 0]], float)


def _log_so3(E: np.ndarray) -> np.ndarray:
    """Rotation vectors (N, 3) of rotation matrices E (N, 3, 3). Near pi the skew part vanishes,
    so the axis comes from the symmetric part (E + E^T)/2 = cos a 1 + (1 - cos a) k k^T: its
    largest diagonal column, signed by the skew part where that is still non-zero."""
    f = E.reshape(-1, 9)
    s = 0.5 * (f[:, [7, 2, 3]] - f[:, [5, 6, 1]])
    ang = np.arccos(np.clip(0.5 * (f[:, 0] + f[:, 4] + f[:, 8] - 1.0), -1.0, 1.0))
    sn = np.sqrt(np.sum(s * s, -1))
    out = s * np.where(sn > 1e-9, ang / np.maximum(sn, 1e-12), 1.0)[:, None]
    near = (ang > np.pi - 1e-3) & (sn < 1e-3 * np.pi)
    if np.any(near):
        Es = E.reshape(-1, 3, 3)[near]
        B = 0.5 * (Es + Es.transpose(0, 2, 1))
        c = np.cos(ang[near])[:, None, None]
        kk = (B - c * np.eye(3)) / np.maximum(1.0 - c, 1e-12)       # k k^T
        diag = np.diagonal(kk, axis1=1, axis2=2)
        j = np.argmax(diag, axis=1)
        col = kk[np.arange(len(j)), :, j]
        k = col / np.sqrt(np.maximum(diag[np.arange(len(j)), j], 1e-12))[:, None]
        sgn = np.where(np.sum(k * s[near], -1) < 0, -1.0, 1.0)[:, None]
        out[near] = sgn * k * ang[near][:, None]
    return out


def simulate_pendulum(handle: PendulumParams, bag_mass: float, t: np.ndarray,
                      robot_position: np.ndarray, robot_velocity: np.ndarray,
                      robot_rotation: np.ndarray, bag_position0: np.ndarray,
                      bag_velocity0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pendulum bag's motion (positions, velocities (T, 3)) when the robot follows a
    recorded motion exactly (as simulate_bag): the swing driven by the robot's acceleration,
    (I + m_b P) w' = -K th - C w - m_b l x a (body frame)."""
    x, v = simulate_pendulums([handle], bag_mass, t, robot_position, robot_velocity,
                              robot_rotation, bag_position0, bag_velocity0)
    return x[0], v[0]


def simulate_pendulums(handles: list[PendulumParams], bag_mass: float, t: np.ndarray,
                       robot_position: np.ndarray, robot_velocity: np.ndarray,
                       robot_rotation: np.ndarray, bag_position0: np.ndarray,
                       bag_velocity0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """simulate_pendulum for B parameter sets at once (positions, velocities (B, T, 3)): the
    system identification's finite-difference Jacobian in one pass."""
    m_b = float(bag_mass)
    K = np.array([h.rot_stiffness for h in handles])
    C = np.array([h.rot_damping for h in handles])
    d = np.array([h.rest_offset for h in handles])
    lv = np.array([h.lever for h in handles])
    hinge = d - lv
    inertia = np.array([h.inertia for h in handles])
    B = len(handles)
    acc = np.zeros_like(robot_velocity)
    acc[1:] = np.diff(robot_velocity, axis=0) / np.diff(t)[:, None]
    acc_b = np.einsum("tji,tj->ti", robot_rotation, acc)          # body frame
    eye = np.eye(3)
    L2 = np.sum(lv * lv, -1)
    J = inertia[:, :, None] * eye + m_b * (L2[:, None, None] * eye - lv[:, :, None] * lv[:, None, :])
    R0 = robot_rotation[0]
    u0 = (np.asarray(bag_position0) - robot_position[0]) @ R0
    ud0 = (np.asarray(bag_velocity0) - robot_velocity[0]) @ R0
    th = np.cross(lv, u0 - d) / L2[:, None]
    om = np.cross(lv, ud0) / L2[:, None]
    T = len(t)
    out_x = np.empty((B, T, 3))
    out_v = np.empty((B, T, 3))
    out_x[:, 0], out_v[:, 0] = bag_position0, bag_velocity0
    cache: dict[float, np.ndarray] = {}
    for i in range(1, T):
        dt = round(float(t[i] - t[i - 1]), 9)
        if dt not in cache:
            cache[dt] = np.linalg.inv(J + dt * C[:, :, None] * eye + dt * dt * K[:, :, None] * eye)
        A = cache[dt]
        rhs = np.einsum("bij,bj->bi", J, om) - dt * K * th - (dt * m_b) * np.cross(lv, acc_b[i])
        om = np.einsum("bij,bj->bi", A, rhs)
        th = th + dt * om
        rl = rotate_by(th, lv)
        R = robot_rotation[i]
        out_x[:, i] = robot_position[i] + (hinge + rl) @ R.T
        out_v[:, i] = robot_velocity[i] + np.cross(om, rl) @ R.T
    return out_x, out_v


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


def handle_from_dict(d: dict) -> "HandleParams | PendulumParams":
    """A handle of config/reduced_models.yaml: `kind: pendulum` or (default) a spring-damper."""
    kinds = {"pendulum": PendulumParams, "rigid_body": RigidBodyParams}
    return kinds.get(d.get("kind"), HandleParams).from_dict(d)


def identified_handles() -> "dict[str, HandleParams | PendulumParams]":
    """Handle parameters per bag model from config/reduced_models.yaml (bench/sysid_bag.py)."""
    from astrobee import config
    try:
        data = config.load_yaml("reduced_models.yaml")
    except config.ConfigError:
        return {}
    return {name: handle_from_dict(d) for name, d in (data.get("handles") or {}).items()}

