"""A pure-numpy free rigid body (no pybullet) for controller tests and quick benches.

The body may carry a rigidly attached payload: then its centre of mass is offset from the
robot point the controller drives, and a force at the robot point also turns the body.
Integration: semi-implicit Euler with body-frame angular velocity and an exact quaternion
update per step.
"""
from __future__ import annotations

import numpy as np

from astrobee import rotations as rot

from .mass import MassProperties
from .pd import State


class RigidBody:
    """Free body; wrenches are given in the BODY frame at the robot point."""

    def __init__(self, mass: MassProperties, position: np.ndarray, orientation: np.ndarray,
                 com_offset_body: np.ndarray | None = None) -> None:
        """`mass.inertia` is about the centre of mass; com_offset_body is the COM relative to
        the robot point (body frame)."""
        self.m = float(mass.mass)
        self.inertia = np.asarray(mass.inertia, float)
        self.inertia_inv = np.linalg.inv(self.inertia)
        self.c = np.zeros(3) if com_offset_body is None else np.asarray(com_offset_body, float)
        self.q = rot.normalize(orientation)
        self.w = np.zeros(3)                     # body frame
        self.x = np.asarray(position, float) + rot.rotate(self.q, self.c)  # COM, world
        self.v = np.zeros(3)                     # COM velocity, world

    def state(self) -> State:
        """Robot-point state in the controller's convention."""
        r_b = -self.c
        pos = self.x + rot.rotate(self.q, r_b)
        vel = self.v + rot.rotate(self.q, np.cross(self.w, r_b))
        return State(pos, vel, self.q.copy(), self.w.copy())

    def step(self, force_body: np.ndarray, torque_body: np.ndarray, dt: float) -> None:
        f_b = np.asarray(force_body, float)
        tau = np.asarray(torque_body, float) + rot.cross(-self.c, f_b)  # about the COM
        self.v = self.v + rot.to_matrix(self.q) @ f_b / self.m * dt
        self.x = self.x + self.v * dt
        wdot = self.inertia_inv @ (tau - rot.cross(self.w, self.inertia @ self.w))
        self.w = self.w + wdot * dt
        self.q = rot.step_body(self.q, self.w * dt)
