"""Bezier algebra: evaluation, derivative control points, Bernstein matrices, jerk cost.

A Bezier curve of degree n on [0, T] is p(t) = sum_i B_{i,n}(t/T) P_i. Its k-th time
derivative is a Bezier curve of degree n-k whose control points are the k-th forward
differences of P scaled by n!/(n-k)! / T^k; convex-hull arguments on those control points
give sufficient conditions for velocity/acceleration limits and box containment.
Shared by the planner (its splines and local plans) and the sampling MPC (its candidates).
"""
from __future__ import annotations

from functools import lru_cache
from math import comb

import numpy as np


@lru_cache(maxsize=None)
def difference_matrix(n: int, k: int) -> np.ndarray:
    """(n+1-k, n+1) matrix D with D @ P = control points of d^k/ds^k of a degree-n curve (s in [0,1])."""
    d = np.eye(n + 1)
    m = n
    for _ in range(k):
        d = m * (d[1:] - d[:-1])
        m -= 1
    d.setflags(write=False)
    return d


@lru_cache(maxsize=None)
def bernstein_power_matrix(n: int) -> np.ndarray:
    """M with B_{i,n}(s) = sum_j M[i, j] s^j (monomial coefficients of each Bernstein polynomial)."""
    m = np.zeros((n + 1, n + 1))
    for i in range(n + 1):
        for j in range(i, n + 1):
            m[i, j] = comb(n, i) * comb(n - i, j - i) * (-1) ** (j - i)
    m.setflags(write=False)
    return m


def bernstein(n: int, s: np.ndarray) -> np.ndarray:
    """Bernstein basis values, shape (len(s), n+1), for parameters s in [0, 1]."""
    s = np.atleast_1d(np.asarray(s, dtype=float))
    i = np.arange(n + 1)
    binom = np.array([comb(n, k) for k in i], dtype=float)
    return binom * s[:, None] ** i * (1.0 - s[:, None]) ** (n - i)


@lru_cache(maxsize=None)
def bernstein_gram(n: int) -> np.ndarray:
    """G[i, j] = integral_0^1 B_{i,n}(s) B_{j,n}(s) ds (closed form)."""
    g = np.zeros((n + 1, n + 1))
    for i in range(n + 1):
        for j in range(n + 1):
            g[i, j] = comb(n, i) * comb(n, j) / (comb(2 * n, i + j) * (2 * n + 1))
    g.setflags(write=False)
    return g


@lru_cache(maxsize=None)
def jerk_cost_matrix(n: int) -> np.ndarray:
    """Q (n+1, n+1): integral_0^1 |d^3 p/ds^3|^2 ds = P^T Q P per axis; over duration T divide by T^5."""
    if n < 3:
        return np.zeros((n + 1, n + 1))
    d3 = difference_matrix(n, 3)
    q = d3.T @ bernstein_gram(n - 3) @ d3
    q = 0.5 * (q + q.T)
    q.setflags(write=False)
    return q


def horner(coefficients: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Polynomials with monomial coefficients (M, n+1, d) (row j multiplies s^j), each at its own
    parameter s (M,): (M, d)."""
    c = np.asarray(coefficients, dtype=float)
    s = np.asarray(s, dtype=float)[:, None]
    out = c[:, -1].copy()
    for j in range(c.shape[1] - 2, -1, -1):
        out *= s
        out += c[:, j]
    return out


@lru_cache(maxsize=None)
def monomial_matrix(n: int, k: int = 0) -> np.ndarray:
    """(n+1-k, n+1) matrix C with C @ P = monomial coefficients in s of d^k/ds^k of a degree-n curve."""
    c = bernstein_power_matrix(n - k).T @ difference_matrix(n, k)
    c.setflags(write=False)
    return c


def evaluate(points: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Curve values at parameters s in [0,1]; points (n+1, d) -> (len(s), d)."""
    points = np.asarray(points, dtype=float)
    return bernstein(len(points) - 1, s) @ points


def derivative_points(points: np.ndarray, duration: float, k: int) -> np.ndarray:
    """Control points of the k-th time derivative of a curve lasting `duration` seconds."""
    points = np.asarray(points, dtype=float)
    n = len(points) - 1
    if k > n:
        return np.zeros((1, points.shape[1]))
    return difference_matrix(n, k) @ points / duration**k


def evaluate_derivative(points: np.ndarray, duration: float, s: np.ndarray, k: int) -> np.ndarray:
    """k-th time derivative at parameters s (curve of `duration` seconds)."""
    return evaluate(derivative_points(points, duration, k), s)


def elevate(points: np.ndarray, degree: int) -> np.ndarray:
    """Degree elevation of a Bezier curve to `degree` (same curve, more control points)."""
    p = np.asarray(points, dtype=float)
    while len(p) - 1 < degree:
        n = len(p) - 1
        i = np.arange(1, n + 1)[:, None] / (n + 1)
        mid = i * p[:-1] + (1 - i) * p[1:]
        p = np.vstack([p[:1], mid, p[-1:]])
    return p


def control_points(p0, v0, a0, p1, v1, a1, duration) -> np.ndarray:
    """Control points (..., 6, 3) of the quintic Bezier from (p0, v0, a0) to (p1, v1, a1) in
    `duration` s: P0 = p0, P1 = p0 + v0 T/5, P2 = p0 + 2 v0 T/5 + a0 T^2/20, mirrored at the end
    (the minimum-jerk curve between two full states); inputs broadcast over leading axes."""
    T = np.asarray(duration, dtype=float)[..., None]
    p0, v0, a0, p1, v1, a1 = (np.asarray(x, dtype=float) for x in (p0, v0, a0, p1, v1, a1))
    P1 = p0 + v0 * T / 5.0
    P2 = p0 + 2.0 * v0 * T / 5.0 + a0 * T * T / 20.0
    P4 = p1 - v1 * T / 5.0
    P3 = p1 - 2.0 * v1 * T / 5.0 + a1 * T * T / 20.0
    return np.stack(np.broadcast_arrays(p0, P1, P2, P3, P4, p1), axis=-2)
