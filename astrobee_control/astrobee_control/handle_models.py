"""The cargo bag's handle models of rollout model A (reduced_model.py) and what fits them.

HandleParams (a body-frame spring-damper + drag), PendulumParams (a rigid box swinging about the
grasp point on a rotational spring-damper), RigidBodyParams (held rigidly, the pair turning),
read per bag model from config/reduced_models.yaml. `simulate_bag` / `simulate_pendulum` drive
the spring / pendulum by a recorded (kinematic) robot motion: what the system identification
(sysid.py) fits.
"""
from __future__ import annotations

from dataclasses import dataclass

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
