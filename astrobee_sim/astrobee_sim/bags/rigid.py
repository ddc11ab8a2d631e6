"""Reduced bag: a rigid URDF box whose handle is a ball joint (point-to-point) at the gripper."""
from __future__ import annotations

import os
import tempfile

import numpy as np

from .rigid_base import RigidPartsBag


def bag_urdf(size, mass: float) -> str:
    x, y, z = size
    I = [mass * (y * y + z * z) / 12, mass * (x * x + z * z) / 12, mass * (x * x + y * y) / 12]
    g = f'<geometry><box size="{x} {y} {z}"/></geometry>'
    return (f'<?xml version="1.0"?><robot name="cargo_bag"><link name="bag">'
            f'<inertial><mass value="{mass}"/><inertia ixx="{I[0]}" iyy="{I[1]}" izz="{I[2]}" '
            f'ixy="0" ixz="0" iyz="0"/></inertial>'
            f'<visual>{g}<material name="tan"><color rgba="0.8 0.65 0.4 1"/></material></visual>'
            f'<collision>{g}</collision></link></robot>')


class RigidBag(RigidPartsBag):
    model = "rigid"

    def __init__(self, client: int, variant: str = "front", size=None, mass=None, **params):
        super().__init__(client, variant, size, mass, **params)
        fd, path = tempfile.mkstemp(suffix=".urdf", prefix="bag_")
        with os.fdopen(fd, "w") as f:
            f.write(bag_urdf(self.size, self.mass))
        try:
            b = self.p.loadURDF(path, flags=self.p.URDF_USE_INERTIA_FROM_FILE, useMaximalCoordinates=True,
                                physicsClientId=client)
        finally:
            os.unlink(path)
        self.p.changeDynamics(b, -1, linearDamping=0, angularDamping=0, physicsClientId=client,
                              activationState=self.p.ACTIVATION_STATE_DISABLE_SLEEPING)
        self.parts = [b]
        self.offsets = np.zeros((1, 3))
        self.half_extents = [self.size / 2]

    def grasp(self, k: int, robot) -> None:
        """The grasp model's joint at the handle (strap: the ball joint this model always had,
        now with the twist spring; clamp: a fixed joint), max_force shared by its points."""
        self.hold_handle(k, robot, 0, float(self.params.get("max_force", 500.0)))
        self.ignore_collisions_with(robot.id)
