"""The reduced pair model, linearised for the wrench MPC: robot + bag about the present attitude.

State (25): the pair's centre as held, p = robot + R c (c = m_b / M times the bag's rest
offset), and v, in the frame of the present attitude R0 (the dynamics then do not depend on
R0 and their discretisation is cached); it is the centre of mass when the bag hangs at rest and
moves with the swing's reaction, M v' = a_F + m_b [l]x phi'' (the pair law tracks it too); the attitude offset
delta from R0 (body rotation vector) and rate w (body); the bag's swing about the grasp phi, phi'
(body rotation vector of the grasp -> bag lever); the progress s (s of the nominal's clock); the
applied wrench a (6, body: the propulsion lag's state). Input (7): the commanded body wrench u
and the progress rate sigma. With R0 fixed over the horizon the model is linear:

    M v'  = a_F + m_b [l]x phi''         I w' = a_T - lever x a_F
    J phi'' = -K phi - C phi' - (m_b / M) l x a_F          s' = sigma
    a' = (u - a) / lag                  (lag 0: a = u)

(the swing equation is the pendulum of reduced_model.PendulumParams; K, C per body axis, the
strap's figures of pair_model.PairParams). Robot and bag centres are linear in the state
(`positions`), which is what the corridor boxes constrain. Re-linearised at every decision
(real-time iteration: one QP per linearisation).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from .allocation import skew

NX, NU = 25, 7
P, V, D, W, PHI, PHID, S, LAG = (slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12),
                                 slice(12, 15), slice(15, 18), slice(18, 19), slice(19, 25))


@dataclass
class PairFigures:
    """What the linear model needs of the pair (robot body frame)."""

    mass: float               # kg, robot + bag
    bag_mass: float
    inertia: np.ndarray       # (3, 3) about the point the pair turns about
    lever: np.ndarray         # (3,) the force's lever (robot -> that point)
    centre: np.ndarray        # (3,) robot -> the pair's centre of mass (bag at rest)
    offset: np.ndarray        # (3,) robot -> bag centre at rest
    grasp: np.ndarray         # (3,) robot -> grasp point
    bag_inertia: np.ndarray   # (3,) kg m^2 about the bag's centre (body axes)
    swing_stiffness: np.ndarray   # (3,) N m/rad
    swing_damping: np.ndarray     # (3,) N m s/rad
    lag: float = 0.0              # s


def continuous(fig: PairFigures) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of x' = A x + B u (module docstring)."""
    A = np.zeros((NX, NX))
    B = np.zeros((NX, NU))
    M, mb = fig.mass, fig.bag_mass
    A[P, V] = np.eye(3)
    A[D, W] = np.eye(3)
    A[PHI, PHID] = np.eye(3)
    I_inv = np.linalg.inv(fig.inertia)
    force_to = {"v": np.eye(3) / M, "w": -I_inv @ skew(fig.lever)}
    torque_to_w = I_inv
    l = fig.offset - fig.grasp
    mu = (M - mb) * mb / M if mb > 0 else 0.0
    if mb > 0:
        J = np.diag(fig.bag_inertia) + mu * (l @ l * np.eye(3) - np.outer(l, l))
        J_inv = np.linalg.inv(J)
        A[PHID, PHI] = -J_inv @ np.diag(fig.swing_stiffness)
        A[PHID, PHID] = -J_inv @ np.diag(fig.swing_damping)
        force_to["phi"] = -(mb / M) * J_inv @ skew(l)
    else:
        force_to["phi"] = np.zeros((3, 3))
    if fig.lag > 0:
        src, cols = A, slice(19, 22)
        A[LAG, LAG] = -np.eye(6) / fig.lag
        B[LAG, :6] = np.eye(6) / fig.lag
        tcols = slice(22, 25)
    else:
        src, cols, tcols = B, slice(0, 3), slice(3, 6)
    src[V, cols] = force_to["v"]
    src[W, cols] = force_to["w"]
    src[W, tcols] = torque_to_w
    src[PHID, cols] = force_to["phi"]
    B[S, 6] = 1.0
    if mb > 0:      # p is the rigid centre (robot + R c): it moves with the swing's reaction
        gl = (mb / M) * skew(l)
        A[V, :] += gl @ A[PHID, :]
        B[V, :] += gl @ B[PHID, :]
    return A, B


def discrete(fig: PairFigures, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold (Ad, Bd) over dt seconds."""
    A, B = continuous(fig)
    blk = np.zeros((NX + NU, NX + NU))
    blk[:NX, :NX], blk[:NX, NX:] = A, B
    E = expm(blk * dt)
    return E[:NX, :NX], E[:NX, NX:]


def positions(fig: PairFigures, R0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                         np.ndarray]:
    """(Cr, cr, Cb, cb): robot centre = Cr x + cr, bag centre = Cb x + cb (world, linear in
    the state about the present attitude R0)."""
    M, mb = fig.mass, fig.bag_mass
    c, d, l = fig.centre, fig.offset, fig.offset - fig.grasp
    Cr = np.zeros((3, NX))
    Cr[:, P] = R0
    Cr[:, D] = R0 @ skew(c)
    Cb = np.zeros((3, NX))
    Cb[:, P] = R0
    Cb[:, D] = -R0 @ skew(d - c)
    Cb[:, PHI] = -R0 @ skew(l)
    return Cr, -R0 @ c, Cb, R0 @ (d - c)
