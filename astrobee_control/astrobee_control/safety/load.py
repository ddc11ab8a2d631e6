"""Mass properties of the robot rigidly holding a load, about the combined centre of mass.

The filter's point accelerations are exact for a rigid body whose centre of mass sits off the
robot point (mass.with_bag gives inertia about the robot point instead, for the PD law)."""
from __future__ import annotations

import numpy as np

from ..mass import MassProperties, box_inertia


def _parallel(m: float, r: np.ndarray) -> np.ndarray:
    return m * (float(r @ r) * np.eye(3) - np.outer(r, r))


def carried_load(robot: MassProperties, load_mass: float, load_size: np.ndarray,
                 offset_body: np.ndarray,
                 rotation_body: np.ndarray | None = None) -> tuple[MassProperties, np.ndarray]:
    """(mass properties about the combined centre of mass, that centre's offset from the robot
    point in the body frame) for `robot` (inertia about its own centre, at the robot point)
    holding a solid box of `load_mass` kg and `load_size` m centred at `offset_body`."""
    d = np.asarray(offset_body, float)
    rb = np.eye(3) if rotation_body is None else np.asarray(rotation_body, float)
    m_r, m_b = float(robot.mass), float(load_mass)
    total = m_r + m_b
    c = m_b * d / total
    inertia = (robot.inertia + _parallel(m_r, -c)
               + rb @ box_inertia(m_b, load_size) @ rb.T + _parallel(m_b, d - c))
    return MassProperties(total, inertia), c
