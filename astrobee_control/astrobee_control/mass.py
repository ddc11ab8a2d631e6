"""Mass properties of the robot, alone or holding a cargo bag, for the controller's feed-forward.

The controller tracks the robot's body frame; a held bag adds its mass and, by the parallel-axis
theorem, inertia about the robot's centre of mass (the bag treated as rigidly held: an
approximation for the ball-joint and soft handles, which is what a flight controller can know).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from astrobee import config


@dataclass(frozen=True)
class MassProperties:
    """Mass (kg) and inertia (3x3, kg m^2, body frame, about the controlled point)."""

    mass: float
    inertia: np.ndarray

    def __post_init__(self) -> None:
        inertia = np.asarray(self.inertia, dtype=float)
        if inertia.shape == (3,):
            inertia = np.diag(inertia)
        if inertia.shape != (3, 3) or not np.all(np.isfinite(inertia)):
            raise ValueError("inertia must be a finite 3-vector or 3x3 matrix")
        if not (np.isfinite(self.mass) and self.mass > 0):
            raise ValueError(f"mass must be positive, got {self.mass}")
        object.__setattr__(self, "inertia", inertia)


def robot() -> MassProperties:
    """Astrobee alone, from config/astrobee.yaml."""
    cfg = config.astrobee()
    return MassProperties(float(cfg["mass"]), np.diag(np.asarray(cfg["inertia"], dtype=float)))


def box_inertia(mass: float, size: np.ndarray) -> np.ndarray:
    """Inertia (3x3, about its centre, own frame) of a solid box of side lengths `size`."""
    x, y, z = np.asarray(size, dtype=float)
    return mass / 12.0 * np.diag([y * y + z * z, x * x + z * z, x * x + y * y])


def with_bag(base: MassProperties, bag_mass: float, bag_size: np.ndarray,
             offset_body: np.ndarray, bag_rotation_body: np.ndarray | None = None) -> MassProperties:
    """Robot plus a held bag whose centre sits at `offset_body` (m, robot body frame).

    Inertia is taken about the robot's centre of mass (the point the controller drives), the
    bag's own inertia rotated into the body frame by `bag_rotation_body` (3x3, bag -> body).
    """
    d = np.asarray(offset_body, dtype=float)
    r = np.eye(3) if bag_rotation_body is None else np.asarray(bag_rotation_body, dtype=float)
    i_bag = r @ box_inertia(bag_mass, bag_size) @ r.T
    parallel = bag_mass * (float(d @ d) * np.eye(3) - np.outer(d, d))
    return MassProperties(base.mass + float(bag_mass), base.inertia + i_bag + parallel)
