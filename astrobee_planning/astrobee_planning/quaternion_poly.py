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
from functools import lru_cache

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


@lru_cache(maxsize=None)
def _antidiagonal(n1: int, n2: int) -> np.ndarray:
    """(n1+n2-1, n1*n2) selector E[k, i*n2 + j] = [i + j == k]: coefficients of polynomial
    products from the outer product of two coefficient vectors."""
    e = np.zeros((n1 + n2 - 1, n1, n2))
    for i in range(n1):
        e[i + np.arange(n2), i, np.arange(n2)] = 1.0
    e = e.reshape(n1 + n2 - 1, n1 * n2)
    e.setflags(write=False)
    return e


def time_coefficients_batch(coefficients: np.ndarray, durations: np.ndarray) -> np.ndarray:
    """`QuaternionPolynomial.time_coefficients` of many pieces at once: (P, 6, 4), (P,) -> (P, 6, 12)."""
    c = np.asarray(coefficients, dtype=float)
    T = np.asarray(durations, dtype=float)[:, None, None]
    k = np.arange(6)[:, None]
    out = np.zeros(c.shape[:-2] + (6, 12))
    out[..., :4] = c
    out[..., :5, 4:8] = k[1:] * c[..., 1:, :] / T
    out[..., :4, 8:12] = k[2:] * (k[2:] - 1) * c[..., 2:, :] / T ** 2
    return out


def rate_coefficients(time_coefficients: np.ndarray) -> np.ndarray:
    """Sampling table of quaternion polynomials from their `time_coefficients` (P, 6, 12):
    (P, 11, 12) monomial coefficients in s of [q (4), |q|^2, q.q', W = vec(q' (x) q*) (3),
    A = vec(q'' (x) q*) (3)]. For the normalised path q/|q| the world rates are then exactly
    w = 2 W / |q|^2 and alpha = 2 A / |q|^2 - 4 (q.q') W / |q|^4 (the q (x) q* terms are
    scalars), so sampling is one matrix product and a few row operations (`rates_from_table`)."""
    c = np.asarray(time_coefficients, dtype=float)
    P = c.shape[0]
    q = c[:, :, :4]
    # R[p, k, a, b]: coefficient of s^k in (c[:, :, a] * q[:, :, b]), a over [q, q', q''] (12)
    outer = c[:, :, None, :, None] * q[:, None, :, None, :]                  # (P, 6, 6, 12, 4)
    R = (_antidiagonal(6, 6) @ outer.reshape(P, 36, 48)).reshape(P, 11, 12, 4)
    x, y, z, w = 0, 1, 2, 3

    def vec_conj(o: int) -> np.ndarray:     # vec(p (x) q*) with p the 4 columns from o
        r = lambda a, b: R[:, :, o + a, b]  # noqa: E731
        return np.stack([r(x, w) - r(w, x) - (r(y, z) - r(z, y)),
                         r(y, w) - r(w, y) - (r(z, x) - r(x, z)),
                         r(z, w) - r(w, z) - (r(x, y) - r(y, x))], axis=-1)
    out = np.zeros((P, 11, 12))
    out[:, :6, :4] = q
    out[:, :, 4] = np.einsum("pkaa->pk", R[:, :, 0:4, :])
    out[:, :, 5] = np.einsum("pkaa->pk", R[:, :, 4:8, :])
    out[:, :, 6:9] = vec_conj(4)
    out[:, :, 9:12] = vec_conj(8)
    return out


def rates_from_table(values: np.ndarray, quat: np.ndarray | None = None,
                     w: np.ndarray | None = None, alpha: np.ndarray | None = None,
                     scratch: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(unit quaternion (4, M), world w (3, M), world alpha (3, M)) from the 12 rows of
    `rate_coefficients` evaluated at M parameters (column-stacked, (12, M)); written into the
    given arrays when passed (scratch: (>= 4, M) work rows)."""
    M = values.shape[1]
    quat = np.empty((4, M)) if quat is None else quat
    w = np.empty((3, M)) if w is None else w
    alpha = np.empty((3, M)) if alpha is None else alpha
    scratch = np.empty((4, M)) if scratch is None else scratch
    two_inv_m, r, tmp = scratch[0], scratch[1], scratch[1:4]
    np.divide(2.0, values[4], out=two_inv_m)                 # 2 / |q|^2
    np.sqrt(two_inv_m, out=r)
    np.multiply(values[:4], r, out=quat)
    quat *= np.sqrt(0.5)                                      # q / |q|
    np.multiply(values[6:9], two_inv_m, out=w)                # 2 W / |q|^2
    np.multiply(values[5], two_inv_m, out=r)                  # 2 q.q' / |q|^2
    np.multiply(values[6:9], r, out=tmp)
    np.subtract(values[9:12], tmp, out=alpha)
    alpha *= two_inv_m                                         # (2 A - 4 q.q' W / |q|^2) / |q|^2
    return quat, w, alpha


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


def peak_rates_batch(polys: list[QuaternionPolynomial], samples: int = 200) -> tuple[float, float]:
    """Largest |w| and |alpha| over several polynomials (each sampled `samples` times), in one
    vectorised evaluation: the same figures as max over `peak_rates` of each."""
    if not polys:
        return 0.0, 0.0
    tab = rate_coefficients(time_coefficients_batch(np.stack([p.coefficients for p in polys]),
                                                    np.array([p.duration for p in polys])))
    V = np.linspace(0.0, 1.0, samples)[:, None] ** np.arange(tab.shape[1])       # (M, 11)
    vals = np.einsum("mj,pjk->kpm", V, tab).reshape(12, -1)                       # (12, P*M)
    _, w, a = rates_from_table(vals)
    return float(np.sqrt((w * w).sum(axis=0).max())), float(np.sqrt((a * a).sum(axis=0).max()))


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
