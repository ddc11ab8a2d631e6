"""Feedback that holds the pair on the oracle's plan: a time-varying LQR on the pair model
linearised along the oracle's solution (robot AND bag states), sampled at the control rate.

The reference is the oracle's own trajectory on the control ticks (each tick integrated from the
last shooting node with that interval's wrench and the bump), so the gains are those of the
model the oracle planned with. Errors are minimal coordinates: position, velocity, the robot's
and the bag's attitude as body-frame rotation vectors, their body rates (and the lag's wrench
when the model has a lag): 18 (or 24) numbers. Jacobians by central differences of the numpy
pair model (pair_model.rk4), all ticks batched; the Riccati recursion runs backwards once.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from astrobee import rotations as rot
from astrobee_control import pair_model as pm

from .solve import OracleResult

# Bryson scales: the error each state may show and the wrench each axis may spend (the box).
# Robot first: the bag's swing about the free pivot axes is not reachable at first order (the
# test of this module), so weighting its error (q_b 1 rad, w_b 0.02 rad/s, SWING_SCALE) drags
# the robot off the plan chasing it: flown, 0.4-0.8 m off and contacts (docs/results/oracle.md)
ERROR_SCALE = {"p": 0.05, "v": 0.01, "q_r": 0.05, "w_r": 0.01, "q_b": 10.0, "w_b": 1.0, "a": 1.0}
SWING_SCALE = {"q_b": 1.0, "w_b": 0.02}
TERMINAL_WEIGHT = 10.0


@dataclass
class TrackingPlan:
    """The oracle's trajectory on the control ticks and the feedback gains along it."""

    t: np.ndarray          # (K,) tick times
    x: np.ndarray          # (K, 26) reference states
    u: np.ndarray          # (K, 6) the oracle's wrench (feed-forward)
    bump: np.ndarray       # (K, 3) the bump's mean force over each tick
    gains: np.ndarray      # (K, 6, n_err)
    lag: bool

    def index(self, t: float) -> int:
        return int(np.clip(np.searchsorted(self.t, t + 1e-9, side="right") - 1, 0, len(self.t) - 1))

    def command(self, x: np.ndarray, t: float, lim: np.ndarray) -> np.ndarray:
        """The body wrench for measured pair state x (26,) at tick time t, boxed."""
        k = self.index(t)
        e = error(x[None], self.x[k][None], self.lag)[0]
        return np.clip(self.u[k] - self.gains[k] @ e, -lim, lim)


def error(x: np.ndarray, ref: np.ndarray, lag: bool) -> np.ndarray:
    """Minimal error coordinates of states x (..., 26) against ref (..., 26)."""
    eq_r = rot.to_rotvec(rot.multiply(rot.conjugate(ref[..., pm.Q_R]), x[..., pm.Q_R]))
    eq_b = rot.to_rotvec(rot.multiply(rot.conjugate(ref[..., pm.Q_B]), x[..., pm.Q_B]))
    parts = [x[..., pm.P_R] - ref[..., pm.P_R], x[..., pm.V_R] - ref[..., pm.V_R], eq_r,
             x[..., pm.W_R] - ref[..., pm.W_R], eq_b, x[..., pm.W_B] - ref[..., pm.W_B]]
    if lag:
        parts.append(x[..., pm.A] - ref[..., pm.A])
    return np.concatenate(parts, axis=-1)


def perturb(x: np.ndarray, d: np.ndarray, lag: bool) -> np.ndarray:
    """x (..., 26) moved by error coordinates d (..., n_err): the inverse of `error`."""
    x = np.broadcast_to(np.asarray(x, float), np.broadcast_shapes(np.shape(x)[:-1], np.shape(d)[:-1]) + (pm.NX,))
    y = np.array(x, float)
    y[..., pm.P_R] += d[..., 0:3]
    y[..., pm.V_R] += d[..., 3:6]
    y[..., pm.Q_R] = rot.multiply(x[..., pm.Q_R], rot.from_rotvec(d[..., 6:9]))
    y[..., pm.W_R] += d[..., 9:12]
    y[..., pm.Q_B] = rot.multiply(x[..., pm.Q_B], rot.from_rotvec(d[..., 12:15]))
    y[..., pm.W_B] += d[..., 15:18]
    if lag:
        y[..., pm.A] += d[..., 18:24]
    return y


def reference(res: OracleResult, params: pm.PairParams, dt: float) -> tuple:
    """(t, x, u, bump) of the oracle's trajectory on ticks of dt from its first node: each tick
    integrated from the last shooting node before it with that interval's wrench."""
    t = np.arange(res.t[0], res.t[-1] - 1e-9, dt)
    k = np.clip(np.searchsorted(res.t, t + 1e-9, side="right") - 1, 0, len(res.u) - 1)
    b = res.bump
    node_bump = np.zeros((len(res.u), 3))
    if b is not None:
        node_bump[np.abs(res.t[:-1] - b.time) < 1e-9] = b.force
    h = t - res.t[k]
    x = res.x[k].copy()
    n = max(1, int(math.ceil(h.max() / 0.05)))
    for _ in range(n):                          # RK4 in steps of <= 0.05 s, per-tick lengths
        x = _rk4_var(x, res.u[k], node_bump[k], params, h / n)
    # the bump as each tick sees it: its mean force over the tick (the impulse kept)
    tick_bump = np.zeros((len(t), 3))
    if b is not None:
        overlap = np.clip(np.minimum(t + dt, b.time + b.duration) - np.maximum(t, b.time), 0, None)
        tick_bump = overlap[:, None] / dt * np.asarray(b.force)[None]
    return t, x, res.u[k], tick_bump


def _rk4_var(x: np.ndarray, u: np.ndarray, b: np.ndarray, p: pm.PairParams, h: np.ndarray) -> np.ndarray:
    """One RK4 step per row with its own step length h (K,)."""
    hh = h[:, None]
    k1 = pm.xdot(x, u, b, p)
    k2 = pm.xdot(x + 0.5 * hh * k1, u, b, p)
    k3 = pm.xdot(x + 0.5 * hh * k2, u, b, p)
    k4 = pm.xdot(x + hh * k3, u, b, p)
    return pm.normalise(x + hh / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4))


def linearise(x: np.ndarray, u: np.ndarray, b: np.ndarray, p: pm.PairParams, dt: float,
              lag: bool, eps: float = 1e-5) -> tuple[np.ndarray, np.ndarray]:
    """A (K, n, n), B (K, n, 6) of the tick step about (x, u, b) in error coordinates
    (central differences, every tick and direction in one batched RK4)."""
    K, n = len(x), (24 if lag else 18)
    eye = np.eye(n) * eps
    xs = np.concatenate([perturb(x[:, None], eye[None], lag), perturb(x[:, None], -eye[None], lag),
                         np.repeat(x[:, None], 12, 1)], 1)                   # (K, 2n + 12, 26)
    du = np.concatenate([np.eye(6), -np.eye(6)]) * eps
    us = np.concatenate([np.repeat(u[:, None], 2 * n, 1), u[:, None] + du[None]], 1)
    nxt = pm.rk4(xs, us, np.repeat(b[:, None], 2 * n + 12, 1), p, dt)
    base = pm.rk4(x, u, b, p, dt)
    e = error(nxt, base[:, None], lag)                                       # (K, 2n + 12, n)
    A = (e[:, :n] - e[:, n:2 * n]).transpose(0, 2, 1) / (2 * eps)
    B = (e[:, 2 * n:2 * n + 6] - e[:, 2 * n + 6:]).transpose(0, 2, 1) / (2 * eps)
    return A, B


def weights(lim: np.ndarray, lag: bool, scale: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Q, R of Bryson's rule: 1 / (allowed error)^2, 1 / (wrench box)^2."""
    s = {**ERROR_SCALE, **(scale or {})}
    keys = ["p", "v", "q_r", "w_r", "q_b", "w_b"] + (["a"] if lag else [])
    q = np.concatenate([np.full(6 if k == "a" else 3, 1.0 / s[k] ** 2) for k in keys])
    if lag:
        q[18:] = 0.0
    return np.diag(q), np.diag(1.0 / np.asarray(lim, float) ** 2)


def plan(res: OracleResult, params: pm.PairParams, lim: np.ndarray, dt: float,
         scale: dict | None = None) -> TrackingPlan:
    """The reference on the ticks and the finite-horizon LQR gains along it."""
    lag = params.lag > 0
    t, x, u, b = reference(res, params, dt)
    A, B = linearise(x, u, b, params, dt, lag)
    Q, R = weights(lim, lag, scale)
    P = TERMINAL_WEIGHT * Q
    gains = np.zeros((len(t), 6, Q.shape[0]))
    for k in range(len(t) - 1, -1, -1):
        Bt = B[k].T @ P
        G = np.linalg.solve(R + Bt @ B[k], Bt @ A[k])
        gains[k] = G
        P = Q + A[k].T @ P @ (A[k] - B[k] @ G)
        P = 0.5 * (P + P.T)
    return TrackingPlan(t, x, u, b, gains, lag)
