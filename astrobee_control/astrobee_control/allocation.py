"""Body-wrench allocation for a robot carrying a bag: a 6-variable box-constrained least squares.

The robot's body force F acts at the robot's centre, `lever` (c, body frame) away from the
pair's centre of mass, so it turns the pair with -c x F on top of the body torque tau. Given the
wanted force (body) and the wanted torque about the pair's centre, the allocation solves

    min  w_f^2 |(F - f_des) / f_lim|^2 + w_t^2 |(tau - c x F - tau_des) / t_lim|^2
    s.t. |F_i| <= f_lim_i,  |tau_i| <= t_lim_i            (the flight mode's per-axis limits)

with w_t >> w_f: attitude first (the weighted problem tends to the lexicographic one as
w_t / w_f grows). Unsaturated, the answer is exact (F = f_des, tau = tau_des + c x f_des);
saturated, the force is bent to make torque about the centre where the torque axes run out.

Solved by a primal-dual active-set method on the normal equations (6x6, a few iterations; the
bench measures it against scipy.optimize.lsq_linear, the fallback when it does not settle).
"""
from __future__ import annotations

import numpy as np

MAX_ITER = 12


def skew(v: np.ndarray) -> np.ndarray:
    """[v]x: skew(v) @ u == cross(v, u)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def problem(f_des: np.ndarray, tau_des: np.ndarray, lever: np.ndarray, f_lim: np.ndarray,
            t_lim: np.ndarray, w_force: float, w_torque: float) -> tuple[np.ndarray, np.ndarray]:
    """(A, b) of the least squares in the scaled variables x = [F / f_lim, tau / t_lim] in
    [-1, 1]^6 (what allocate solves; the tests' brute force and the bench use it too)."""
    f_lim, t_lim = np.asarray(f_lim, float), np.asarray(t_lim, float)
    A = np.zeros((6, 6))
    A[:3, :3] = w_force * np.eye(3)
    A[3:, :3] = -w_torque * (skew(np.asarray(lever, float)) * f_lim[None, :]) / t_lim[:, None]
    A[3:, 3:] = w_torque * np.eye(3)
    b = np.concatenate([w_force * np.asarray(f_des, float) / f_lim,
                        w_torque * np.asarray(tau_des, float) / t_lim])
    return A, b


def box_lsq(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """argmin |A x - b|^2 over x in [-1, 1]^n (A square or tall, full column rank):
    primal-dual active set on H = A^T A; scipy's BVLS when it does not settle."""
    H = A.T @ A
    g = A.T @ b
    n = len(g)
    x = np.clip(np.linalg.solve(H, g), -1.0, 1.0)
    mu = g - H @ x                         # > 0 pushes up (at +1), < 0 pushes down (at -1)
    scale = 1.0 / np.diag(H)               # the multipliers in x's units (a Newton step each)
    prev = None
    for _ in range(MAX_ITER):
        up = x + scale * mu > 1.0
        lo = x + scale * mu < -1.0
        key = (up.tobytes(), lo.tobytes())
        if key == prev:
            break
        prev = key
        free = ~(up | lo)
        x = np.where(up, 1.0, np.where(lo, -1.0, 0.0))
        if free.any():
            rhs = g[free] - H[np.ix_(free, ~free)] @ x[~free]
            x[free] = np.linalg.solve(H[np.ix_(free, free)], rhs)
        mu = g - H @ x
        mu[free] = 0.0
    ok = (np.all(np.abs(x) <= 1.0 + 1e-9) and np.all(mu[x >= 1.0 - 1e-12] >= -1e-9)
          and np.all(mu[x <= -1.0 + 1e-12] <= 1e-9))
    free = np.abs(x) < 1.0 - 1e-12
    ok = ok and bool(np.all(np.abs((g - H @ x)[free]) <= 1e-8 * (1.0 + np.abs(g).max())))
    if ok:
        return np.clip(x, -1.0, 1.0)
    from scipy.optimize import lsq_linear
    return lsq_linear(A, b, bounds=(-np.ones(n), np.ones(n)), method="bvls").x


def allocate(f_des: np.ndarray, tau_des: np.ndarray, lever: np.ndarray, f_lim: np.ndarray,
             t_lim: np.ndarray, w_force: float = 1.0, w_torque: float = 30.0
             ) -> tuple[np.ndarray, np.ndarray]:
    """(F, tau) body wrench within the limits (module docstring): f_des the wanted body force
    (N), tau_des the wanted torque about the pair's centre (N m, body), lever the robot ->
    centre vector (m, body)."""
    f_lim, t_lim = np.asarray(f_lim, float), np.asarray(t_lim, float)
    A, b = problem(f_des, tau_des, lever, f_lim, t_lim, w_force, w_torque)
    x = box_lsq(A, b)
    return x[:3] * f_lim, x[3:] * t_lim


def guard(f_des: np.ndarray, tau_des: np.ndarray, lever: np.ndarray, f_lim: np.ndarray,
          t_lim: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F, tau): the wanted force, its part across the lever cut back only as far as its
    torque about the pair's centre (-c x F) would take from a wanted torque the body torque can
    no longer meet; tau = tau_des + c x F, clipped. Unlike allocate, the force is never bent to
    make torque (the route is not traded for attitude), it only stops opposing the attitude.

    Per axis i the kept share s of the cross-lever force obeys |tau_des_i + s t_i| <=
    max(t_lim_i, |tau_des_i|), t = c x F_perp the torque the robot must add to cancel it."""
    f_lim, t_lim = np.asarray(f_lim, float), np.asarray(t_lim, float)
    c = np.asarray(lever, float)
    tau_des = np.asarray(tau_des, float)
    F = np.clip(np.asarray(f_des, float), -f_lim, f_lim)
    n = float(np.linalg.norm(c))
    if n > 1e-9:
        u = c / n
        F_par = (F @ u) * u
        t = np.cross(c, F - F_par)              # what tau must add to cancel the force's torque
        s = 1.0
        for i in range(3):
            if t[i] == 0.0:
                continue
            bound = max(t_lim[i], abs(tau_des[i]))
            # |tau_des_i + s t_i| <= bound, s in [0, 1]: the largest s (0 if tau_des_i is at it)
            hi = (bound - tau_des[i]) / t[i] if t[i] > 0 else (-bound - tau_des[i]) / t[i]
            s = min(s, max(0.0, hi))
        F = F_par + s * (F - F_par)
        # back into the box by a common factor: the force's torque shrinks with it, so every
        # axis's bound still holds (the feasible torques form an interval around 0)
        F = F * min(1.0, float(np.min(f_lim / np.maximum(np.abs(F), 1e-300))))
    tau = np.clip(tau_des + np.cross(c, F), -t_lim, t_lim)
    return F, tau


def keep_along(F: np.ndarray, tau: np.ndarray, f_des: np.ndarray, u: np.ndarray,
               tau_des: np.ndarray, lever: np.ndarray, f_lim: np.ndarray, t_lim: np.ndarray,
               brake_only: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(F, tau): the allocated wrench with its force's component along the unit body
    direction u (the route's) put back to the wanted force's (brake_only: only where the
    allocation pushed further along u than wanted, so the lever may slow the pair but never
    carry it ahead of its route), clipped to the box, and tau the body torque that then best
    meets tau_des about the pair's centre (unchanged when the force is). A force bent along the
    route to turn the pair costs distance the pair must come back over before the budget ends;
    across the route the walls (the clearance weight) bound it."""
    F, u = np.asarray(F, float), np.asarray(u, float)
    f_lim, t_lim = np.asarray(f_lim, float), np.asarray(t_lim, float)
    want = float(np.clip(np.asarray(f_des, float), -f_lim, f_lim) @ u)
    have = float(F @ u)
    if (brake_only and have <= want) or have == want:
        return F, np.asarray(tau, float)
    F = np.clip(F + (want - have) * u, -f_lim, f_lim)
    return F, np.clip(np.asarray(tau_des, float) + np.cross(lever, F), -t_lim, t_lim)


def cost(F: np.ndarray, tau: np.ndarray, f_des: np.ndarray, tau_des: np.ndarray,
         lever: np.ndarray, f_lim: np.ndarray, t_lim: np.ndarray, w_force: float = 1.0,
         w_torque: float = 30.0) -> float:
    """The allocation's objective at (F, tau) (tests and bench compare solvers by it)."""
    r_f = w_force * (np.asarray(F) - f_des) / f_lim
    r_t = w_torque * (np.asarray(tau) - np.cross(lever, F) - tau_des) / t_lim
    return float(r_f @ r_f + r_t @ r_t)
