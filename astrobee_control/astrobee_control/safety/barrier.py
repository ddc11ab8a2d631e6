"""The high-order (relative degree two) control barrier condition used per box face.

For a face with signed distance h (>= 0 inside) of an envelope point, the filter asks

    h_ddot + alpha1'(h) h_dot + k2 (h_dot + alpha1(h)) >= 0                       (1)

which is the high-order CBF chain h1 = h_dot + alpha1(h) >= 0, h1_dot + k2 h1 >= 0. With a
linear alpha1(h) = k1 h this is the exponential CBF h_ddot + (k1 + k2) h_dot + k1 k2 h >= 0; a
linear alpha1 however lets the robot reach speeds far from a wall that its thrusters cannot
brake in time (the required deceleration on the boundary h1 = 0 is k1 * speed). We shape alpha1
by the braking capacity a_b instead:

    alpha1(h) = sqrt(2 a_b h + c^2) - c,   c = a_b / k1        (h >= 0)
    alpha1(h) = k1 h                                            (h < 0, continuous slope k1)

so h1 >= 0 says "the approach speed is below the speed from which a_b stops the point before
the face" (sqrt(2 a_b h) far away, k1 h close in) and the deceleration (1) demands on that
boundary is alpha1' * alpha1 <= a_b: always within the thrusters when a_b is a fraction of what
they can deliver along any direction. Everything here is vectorised over faces.
"""
from __future__ import annotations

import numpy as np


def alpha1(h: np.ndarray, a_brake: float, k1: float) -> tuple[np.ndarray, np.ndarray]:
    """(alpha1(h), alpha1'(h)) elementwise for braking deceleration a_brake (m/s^2) and the
    slope k1 (1/s) at the face."""
    c = a_brake / k1
    root = np.sqrt(2.0 * a_brake * np.maximum(h, 0.0) + c * c)
    inside = h >= 0.0
    val = np.where(inside, root - c, k1 * h)
    slope = np.where(inside, a_brake / root, k1)
    return val, slope


def required_accel(h: np.ndarray, h_dot: np.ndarray, a_brake: float, k1: float,
                   k2: float) -> tuple[np.ndarray, np.ndarray]:
    """Lower bound on h_ddot from (1), and the first-order barrier h1 = h_dot + alpha1(h)."""
    a, da = alpha1(h, a_brake, k1)
    h1 = h_dot + a
    return -da * h_dot - k2 * h1, h1
