"""Reference paths of the sampling MPC: quintic Bezier candidates sampled, the chosen head
joined to the nominal's tail, a final pose held longer, interpolation on the nominal."""
from __future__ import annotations

import numpy as np

from astrobee import bezier

from .reference import SampledTrajectory


def joined(head: tuple, nom: SampledTrajectory, tail: np.ndarray,
            shift: float = 0.0) -> SampledTrajectory:
    """The executed head (t, p, v, a, q, w, alpha) followed by the nominal's samples `tail`
    (their times moved by `shift`)."""
    t, p, v, a, q, w, al = head
    return SampledTrajectory(np.concatenate([t, nom.t[tail] + shift]),
                             np.concatenate([p, nom.position[tail]]),
                             np.concatenate([v, nom.velocity[tail]]),
                             np.concatenate([a, nom.accel[tail]]),
                             np.concatenate([q, nom.orientation[tail]]),
                             np.concatenate([w, nom.omega[tail]]),
                             np.concatenate([al, nom.alpha[tail]]))


def interp(t: np.ndarray, values: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Per-axis linear interpolation of (T, k) samples at times `at` (...,) -> (..., k),
    clamped at the ends."""
    at = np.asarray(at, float)
    return np.stack([np.interp(at.ravel(), t, values[:, k]) for k in range(values.shape[1])],
                    -1).reshape(at.shape + (values.shape[1],))


def append_hold(traj: SampledTrajectory, t_end: float) -> SampledTrajectory:
    """`traj` followed by its final pose held (at rest) until t_end."""
    final = traj.final()
    z = np.zeros(3)
    return SampledTrajectory(np.append(traj.t, t_end), np.vstack([traj.position, final.position]),
                             np.vstack([traj.velocity, z]), np.vstack([traj.accel, z]),
                             np.vstack([traj.orientation, final.orientation]),
                             np.vstack([traj.omega, z]), np.vstack([traj.alpha, z]))


def bezier_states(points: np.ndarray, T: float, s: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities, accelerations (N, M, 3) of quintic Beziers (N, 6, 3) of duration
    T at normalised times s (M,)."""
    B0 = bezier.bernstein(5, s)
    B1 = bezier.bernstein(4, s) @ bezier.difference_matrix(5, 1)
    B2 = bezier.bernstein(3, s) @ bezier.difference_matrix(5, 2)
    return (np.einsum("mi,nik->nmk", B0, points), np.einsum("mi,nik->nmk", B1, points) / T,
            np.einsum("mi,nik->nmk", B2, points) / (T * T))


def interp_quat(traj: SampledTrajectory, times: np.ndarray) -> np.ndarray:
    """Orientation of a trajectory at many times: componentwise linear interpolation of its
    (hemisphere-aligned) samples, renormalised (a fine stand-in for slerp at 10 Hz samples)."""
    q = np.stack([np.interp(times, traj.t, traj.orientation[:, k]) for k in range(4)], -1)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)
