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

The handle models and `simulate_bag` / `simulate_pendulum` (what the system identification,
sysid.py, fits) live in handle_models.py.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from .handle_models import HandleParams, PendulumParams, RigidBodyParams, rotate_by, swing_from_offset


ATTITUDE_STEP = 0.2   # s, the turning rollout's attitude step (its dynamics are slow: torque-limited)


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
