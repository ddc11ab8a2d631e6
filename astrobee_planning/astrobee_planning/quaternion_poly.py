"""Fifth-order quaternion polynomials with boundary orientation, angular velocity and acceleration.

Convention: angular velocity w and acceleration alpha are in the WORLD frame (as in ControlState):
    q_dot  = 0.5 [w, 0] (x) q
    q_ddot = 0.5 [alpha, 0] (x) q + 0.5 [w, 0] (x) q_dot = 0.5 [alpha, 0] (x) q - |w|^2/4 q
The -|w|^2/4 term multiplies the whole quaternion q ([w,0](x)[w,0] = [0, -|w|^2] is a pure
SCALAR); putting it on the vector part is the known bug. With it right, the normalised polynomial
q(s)/|q(s)| meets q, w and alpha exactly at both ends (|q| has zero first and second derivative
there). Rates are recovered from the normalised polynomial: w = vec(2 q_dot (x) q*),
alpha = vec(2 q_ddot (x) q*). Quaternions are [x, y, z, w]. Body-frame rates: rotate_inverse(q, .).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from astrobee import rotations as rot

# Quintic Hermite: monomial coefficients c = H @ [f0, d0, dd0, f1, d1, dd1] (derivatives in s).
_H = np.linalg.inv(np.array([
    [1, 0, 0, 0, 0, 0],
    [0, 1, 0, 0, 0, 0],
    [0, 0, 2, 0, 0, 0],
    [1, 1, 1, 1, 1, 1],
    [0, 1, 2, 3, 4, 5],
    [0, 0, 2, 6, 12, 20],
], dtype=float))
_H.setflags(write=False)


def _pure(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return np.concatenate([v, np.zeros(v.shape[:-1] + (1,))], axis=-1)


def quat_derivatives(q: np.ndarray, w: np.ndarray, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q_dot, q_ddot) of a unit quaternion with world-frame angular velocity w and acceleration alpha."""
    q = np.asarray(q, dtype=float)
    w = np.asarray(w, dtype=float)
    qd = 0.5 * rot.multiply(_pure(w), q)
    qdd = 0.5 * rot.multiply(_pure(alpha), q) - 0.25 * np.sum(w * w, axis=-1, keepdims=True) * q
    return qd, qdd


def rates_from_derivatives(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray]:
    """World-frame (w, alpha) of a unit quaternion path from its first two derivatives."""
    qc = rot.conjugate(q)
    return 2.0 * rot.multiply(qd, qc)[..., :3], 2.0 * rot.multiply(qdd, qc)[..., :3]


def _vec_times_conj(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Vector part of p (x) conj(q) for column-stacked quaternions (4, M): -p_w q_v + q_w p_v - p_v x q_v."""
    px, py, pz, pw = p
    qx, qy, qz, qw = q
    return np.stack([qw * px - pw * qx - (py * qz - pz * qy),
                     qw * py - pw * qy - (pz * qx - px * qz),
                     qw * pz - pw * qz - (px * qy - py * qx)])


def normalised_rates_columns(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """normalised_rates on column-stacked arrays (4, M) -> (4, M), (3, M), (3, M): every
    operation on contiguous rows (the fast layout for long samplings)."""
    m = (q * q).sum(axis=0)
    qq1 = (q * qd).sum(axis=0)
    qq2 = (qd * qd).sum(axis=0) + (q * qdd).sum(axis=0)
    r = 1.0 / np.sqrt(m)
    r3 = r * r * r
    qn = q * r
    qnd = qd * r - q * (qq1 * r3)
    qndd = qdd * r - qd * (2.0 * qq1 * r3) + q * ((3.0 * qq1 * qq1 * r * r - qq2) * r3)
    return qn, 2.0 * _vec_times_conj(qnd, qn), 2.0 * _vec_times_conj(qndd, qn)


def normalised_rates(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(unit quaternion, world w, world alpha) of the normalised path q/|q| from the raw
    polynomial's value and first two time derivatives, rows of (M, 4) arrays."""
    qn, w, a = normalised_rates_columns(q.T, qd.T, qdd.T)
    return qn.T, w.T, a.T


@dataclass
class QuaternionPolynomial:
    """q(s) = sum_k c_k s^k, s = (t - t0) / duration in [0, 1], normalised when evaluated."""
    coefficients: np.ndarray   # (6, 4), rows c_0..c_5, each [x, y, z, w]
    t0: float
    duration: float

    @classmethod
    def from_boundary(cls, q0, w0, a0, q1, w1, a1, duration: float, t0: float = 0.0
                      ) -> "QuaternionPolynomial":
        """Polynomial meeting orientation, world angular velocity and acceleration at both ends."""
        if not duration > 0:
            raise ValueError("duration must be positive")
        q0 = rot.normalize(q0)
        q1 = rot.normalize(q1)
        if np.dot(q0, q1) < 0:
            q1 = -q1
        d0, dd0 = quat_derivatives(q0, w0, a0)
        d1, dd1 = quat_derivatives(q1, w1, a1)
        T = float(duration)
        f = np.stack([q0, T * d0, T * T * dd0, q1, T * d1, T * T * dd1])
        return cls(_H @ f, float(t0), T)

    def raw(self, s: np.ndarray, k: int = 0) -> np.ndarray:
        """k-th s-derivative of the (unnormalised) polynomial at s, shape (len(s), 4)."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        powers = np.arange(6)
        c = self.coefficients
        for _ in range(k):
            c = (powers[1:len(c)][:, None] * c[1:])
            powers = np.arange(len(c))
        return (s[:, None] ** np.arange(len(c))) @ c

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, w, alpha) at times t: unit quaternion, world angular velocity and acceleration."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        T = self.duration
        s = np.clip((t - self.t0) / T, 0.0, 1.0)
        V = s[:, None] ** np.arange(6)
        raw = V @ self.time_coefficients()
        return normalised_rates(raw[:, :4], raw[:, 4:8], raw[:, 8:])

    def time_coefficients(self) -> np.ndarray:
        """(6, 12) monomial coefficients in s of [q, dq/dt, d2q/dt2] (raw, unnormalised)."""
        c = np.asarray(self.coefficients, dtype=float)
        T = self.duration
        k = np.arange(6)[:, None]
        d1 = np.zeros_like(c)
        d1[:5] = k[1:] * c[1:] / T
        d2 = np.zeros_like(c)
        d2[:4] = k[2:] * (k[2:] - 1) * c[2:] / T**2
        return np.hstack([c, d1, d2])

    def peak_rates(self, samples: int = 200) -> tuple[float, float]:
        """Largest |w| and |alpha| over the polynomial (dense sampling)."""
        _, w, a = self.evaluate(self.t0 + np.linspace(0, self.duration, samples))
        return float(np.max(np.linalg.norm(w, axis=1))), float(np.max(np.linalg.norm(a, axis=1)))


def reorientation(q0: np.ndarray, q1: np.ndarray, omega_max: float, alpha_max: float,
                  t0: float = 0.0, min_duration: float = 0.0) -> QuaternionPolynomial:
    """Rest-to-rest reorientation from q0 to q1, as short as the rate limits allow (retimed until
    the sampled |w| <= omega_max and |alpha| <= alpha_max)."""
    theta = rot.angle_between(q0, q1)
    if not (omega_max > 0 and alpha_max > 0):
        raise ValueError("angular limits must be positive")
    # quintic smoothstep: peak rate 1.875 theta / T, peak accel 5.774 theta / T^2
    T = max(1.875 * theta / omega_max, np.sqrt(5.7735 * theta / alpha_max), min_duration, 1e-3)
    z = np.zeros(3)
    for _ in range(30):
        p = QuaternionPolynomial.from_boundary(q0, z, z, q1, z, z, T, t0)
        wm, am = p.peak_rates(400)
        k = max(wm / omega_max, np.sqrt(am / alpha_max))
        if k <= 0.999:
            return p
        T *= max(k, 1.0) * 1.01
    return p
