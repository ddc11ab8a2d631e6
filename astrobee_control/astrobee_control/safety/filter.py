"""CBF-QP safety filter: the closest body-frame wrench to a nominal one that keeps the robot's
envelope (and a carried load) inside the keep-in box union, within the flight mode's limits.

Each tick, for every envelope point (robot sphere, carried-bag corners or sphere) the filter
picks one candidate box (geometry.corridor_boxes, or boxes the caller passes: e.g. the plan's
next ones): the box that maximises the point's smallest first-order barrier h1 = h_dot +
alpha1(h) over its six faces, boxes that contain the point first. Each face of that box gives
one linear constraint on the wrench (barrier.required_accel: relative degree two, position ->
force); the point's acceleration is exact for a rigid body whose centre of mass may sit off
the robot point (a carried load):

    a_pt (body) = F/m + alpha x e + w x (w x e),  alpha = I^-1 (tau - c x F - w x I w),
    e = point offset - c (from the centre of mass c).

The angular rate has a barrier of its own (relative degree one, torque -> angular
acceleration): h_w = w_max^2 - |w|^2 >= 0 with w_max the flight mode's hard_limit_omega, asked
as h_w_dot + k_w h_w >= 0, i.e. -2 w . alpha(F, tau) + k_w h_w >= 0 (one row, linear in the
wrench). The carried bag is modelled as rigidly held, so its swing has no barrier of its own.

The QP (variables F, tau in the body frame and one slack s >= 0 shared by all barrier rows,
in units of the braking deceleration, or of the angular one for the rate row):

    min  sum_i ((F_i - F_nom,i) / Fmax_i)^2 + sum_i ((tau_i - tau_nom,i) / taumax_i)^2
         + rho2 s^2 + rho1 s
    s.t. (n_b . a_pt(F, tau) - required_accel) / a_brake + s >= 0  (per face of each point's box)
         (-2 w . alpha(F, tau) + k_w h_w) / (2 w_max alpha_brake) + s >= 0   (angular rate)
         |F_i| <= Fmax_i, |tau_i| <= taumax_i                (flight mode's propulsion limits)

is set up in OSQP once (dense 7-column constraint pattern sized for `max_points` points) and
only its vectors and matrix values are updated each tick; OSQP warm-starts from the last
solution. When the clipped nominal wrench already satisfies every barrier row the QP is not
solved at all and the nominal wrench is returned unchanged (transparent). When the soft QP needs
a slack above `slack_tol` (the hard QP is infeasible: the robot starts outside, or moves too fast
at a wall) or OSQP fails, the filter returns the maximum braking wrench (force opposing the
velocity, torque opposing the angular velocity, scaled to the limits) and says so.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import osqp
from scipy import sparse

from astrobee.flight_modes import FlightMode

from ..mass import MassProperties
from ..pd import State
from . import barrier, geometry
from .geometry import BodySphere

N_VAR = 7           # F (3), tau (3), slack
INF = 1e30
SLACK_QUAD = 100.0     # cost of the slack (in braking decelerations): quadratic + linear
SLACK_LIN = 100.0


@dataclass
class SafetyResult:
    """One filter step. force/torque: the wrench to send (BODY frame)."""

    force: np.ndarray
    torque: np.ndarray
    active: bool                 # the barriers changed the command (the QP was solved)
    feasible: bool               # the hard CBF constraints could be met (slack <= slack_tol)
    fallback: bool               # the maximum braking wrench was sent instead
    delta_norm: float            # |wrench - nominal wrench| (N and N m stacked)
    slack: float                 # QP slack, in units of the braking deceleration (0 if unused)
    barriers: np.ndarray         # (points, 6) h of each point's active-box faces (m)
    barriers_h1: np.ndarray      # (points, 6) first-order barriers h_dot + alpha1(h) (m/s)
    boxes: np.ndarray            # (points,) index of each point's active box in the candidates
    reason: str = ""             # why the fallback was taken, or "" when none
    omega_barrier: float = float("inf")   # w_max^2 - |w|^2 (rad^2/s^2); inf: no rate limit
    min_barrier: float = field(init=False)

    def __post_init__(self) -> None:
        self.min_barrier = float(self.barriers.min()) if self.barriers.size else float("inf")


def _skew(v: np.ndarray) -> np.ndarray:
    """(..., 3) -> (..., 3, 3) cross-product matrices."""
    out = np.zeros(v.shape + (3,))
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    out[..., 0, 1], out[..., 0, 2] = -z, y
    out[..., 1, 0], out[..., 1, 2] = z, -x
    out[..., 2, 0], out[..., 2, 1] = -y, x
    return out


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (numpy's np.cross costs ~10 us a call)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix (body -> world) of an [x, y, z, w] quaternion (normalised here)."""
    x, y, z, w = q / np.sqrt(q @ q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


class SafetyFilter:
    """CBF-QP safety filter between a controller and the robot (no transport)."""

    def __init__(self, flight_mode: FlightMode, mass: MassProperties, *,
                 com_offset: np.ndarray | None = None, boxes: np.ndarray | None = None,
                 margin: float = 0.05, robot_radius: float | None = None,
                 brake_fraction: float = 0.5, k1: float = 1.0, k2: float = 1.0,
                 k_omega: float = 5.0, slack_tol: float = 0.05, max_points: int = 9) -> None:
        """flight_mode: force/torque limits. mass: mass and inertia about the centre of mass,
        which sits at `com_offset` (body frame) from the robot point (default: at it).
        boxes: candidate boxes (default: the station's keep-in boxes grown by `margin` and
        their merged chains, geometry.corridor_boxes). margin: how far (m) the filter's
        boundary sits outside the keep-in boxes (the simulator's walls sit wall_margin=0.10 m
        outside them, so 0.05 keeps >= 5 cm to the walls while leaving the planner's whole
        safe set free). brake_fraction: share of the weakest axis's force used as the braking
        deceleration of the barriers (<= 1/sqrt(3) keeps a corner's three faces feasible
        together). k1, k2 (1/s): barrier slopes at a face. k_omega (1/s): slope of the angular
        rate barrier (|w| <= the flight mode's hard_limit_omega; none when that is 0).
        slack_tol: slack (in braking decelerations) above which the hard QP counts as
        infeasible."""
        self.robot = geometry.robot_sphere(robot_radius)
        self.margin = float(margin)
        self.boxes = (geometry.corridor_boxes(margin=self.margin) if boxes is None
                      else np.array(boxes, dtype=float, ndmin=2))
        self.brake_fraction = float(brake_fraction)
        self.k1, self.k2 = float(k1), float(k2)
        self.k_omega = float(k_omega)
        self.slack_tol = float(slack_tol)
        self._prev_box: dict[int, int] = {}
        self._solver: osqp.OSQP | None = None
        self._max_points = int(max_points)
        self.set_mass(mass, com_offset)
        self.set_flight_mode(flight_mode)

    # ---- configuration -----------------------------------------------------------------------
    def set_flight_mode(self, mode: FlightMode) -> None:
        """New force/torque limits: the QP's bounds and weights change, not its structure."""
        self.flight_mode = mode
        self.f_max = np.asarray(mode.max_force, float).copy()
        self.t_max = np.asarray(mode.max_torque, float).copy()
        self._limits_changed()

    def set_mass(self, mass: MassProperties, com_offset: np.ndarray | None = None) -> None:
        """New mass properties (inertia about the centre of mass at `com_offset`)."""
        self.mass = mass
        self.com = np.zeros(3) if com_offset is None else np.asarray(com_offset, float).copy()
        self.inertia = np.asarray(mass.inertia, float)
        self.inertia_inv = np.linalg.inv(self.inertia)
        if hasattr(self, "f_max"):
            self._limits_changed()

    def _limits_changed(self) -> None:
        enabled = self.flight_mode.control_enabled and np.all(self.f_max > 0)
        self.a_brake = (self.brake_fraction * float(self.f_max.min()) / self.mass.mass
                        if enabled else 0.0)
        # the QP works in scaled variables z = (F / Fmax, tau / taumax, s): bounds [-1, 1] and a
        # unit-diagonal cost, barrier rows in braking decelerations (OSQP converges in tens of
        # iterations on this scaling instead of hundreds in SI units)
        self._scale = np.concatenate([np.maximum(self.f_max, 1e-6), np.maximum(self.t_max, 1e-6)])
        # angular rate limit and the angular deceleration that scales its barrier row
        self.omega_max = float(self.flight_mode.hard_limit_omega) if enabled else 0.0
        self.alpha_brake = (self.brake_fraction * float(self.t_max.min())
                            / float(np.linalg.eigvalsh(self.inertia).max()) if enabled else 0.0)
        self._p_diag = np.array([2.0] * 6 + [2.0 * SLACK_QUAD])

    # ---- the QP --------------------------------------------------------------------------------
    def _setup(self, n_points: int) -> None:
        """Build the OSQP problem for up to n_points envelope points (once, or on growth)."""
        self._max_points = max(self._max_points, n_points)
        m = 6 + 1 + 1 + 6 * self._max_points      # bounds, slack >= 0, rate row, face rows
        self._m = m
        a = np.zeros((m, N_VAR))
        a[:7, :7] = np.eye(7)
        # dense column pattern so value updates never change the sparsity
        indptr = np.arange(0, m * N_VAR + 1, m)
        indices = np.tile(np.arange(m), N_VAR)
        self._a = a
        a_csc = sparse.csc_matrix((a.ravel(order="F"), indices, indptr), shape=(m, N_VAR))
        p_csc = sparse.csc_matrix(sparse.diags(self._p_diag))
        self._l = np.full(m, -INF)
        self._u = np.full(m, INF)
        self._l[6] = 0.0
        self._solver = osqp.OSQP()
        self._solver.setup(P=p_csc, q=np.zeros(N_VAR), A=a_csc, l=self._l, u=self._u,
                           verbose=False, warm_starting=True, polishing=False,
                           eps_abs=1e-6, eps_rel=1e-6, max_iter=4000, adaptive_rho=True)

    # ---- one tick -----------------------------------------------------------------------------
    def filter(self, force: np.ndarray, torque: np.ndarray, state: State,
               extent: Sequence[BodySphere] = (), boxes: np.ndarray | None = None) -> SafetyResult:
        """The safe wrench closest to the nominal body-frame (force, torque) for `state`
        (position, velocity: world, of the robot point; orientation [x,y,z,w] body -> world;
        omega: body). extent: envelope points of a carried load (body frame), besides the
        robot's own sphere. boxes: candidate boxes for this call (default: the filter's)."""
        f_nom = np.asarray(force, float).reshape(3)
        t_nom = np.asarray(torque, float).reshape(3)
        pos = np.asarray(state.position, float).reshape(3)
        vel = np.asarray(state.velocity, float).reshape(3)
        q = np.asarray(state.orientation, float).reshape(4)
        w = np.asarray(state.omega, float).reshape(3)
        for name, v in (("force", f_nom), ("torque", t_nom), ("position", pos),
                        ("velocity", vel), ("orientation", q), ("omega", w)):
            if not np.all(np.isfinite(v)):
                raise ValueError(f"safety filter: non-finite {name}")
        if not q @ q > 0:
            raise ValueError("safety filter: zero quaternion")
        cand = self.boxes if boxes is None else np.array(boxes, dtype=float, ndmin=2)
        spheres = [self.robot, *extent]
        n_pts = len(spheres)
        if self._solver is None or n_pts > self._max_points:
            self._setup(n_pts)

        r = _matrix(q)
        d = np.array([s.offset for s in spheres], float).reshape(n_pts, 3)   # body offsets
        rad = np.array([s.radius for s in spheres], float)
        p_w = pos + d @ r.T
        v_w = vel + _cross(w, d) @ r.T

        # barrier values of every point in every candidate box: faces [+x +y +z -x -y -z]
        # normals (lo faces point +e, hi faces -e)
        h_lo = p_w[:, None, :] - cand[None, :, :3] - rad[:, None, None]
        h_hi = cand[None, :, 3:] - p_w[:, None, :] - rad[:, None, None]
        h_all = np.concatenate([h_lo, h_hi], axis=2)                       # (P, B, 6)
        hd = np.concatenate([v_w, -v_w], axis=1)                           # (P, 6)
        a1, _ = barrier.alpha1(h_all, max(self.a_brake, 1e-9), self.k1)
        score = (hd[:, None, :] + a1).min(axis=2)                          # (P, B)
        inside = h_all.min(axis=2) >= -1e-9
        score = np.where(inside, score, score - 1e3)
        for i in range(n_pts):                 # hysteresis: keep the last box when as good
            j = self._prev_box.get(i)
            if j is not None and j < len(cand):
                score[i, j] += 1e-4
        sel = score.argmax(axis=1)
        self._prev_box = {i: int(j) for i, j in enumerate(sel)}
        h = h_all[np.arange(n_pts), sel]                                   # (P, 6)
        need, h1 = barrier.required_accel(h, hd, max(self.a_brake, 1e-9), self.k1, self.k2)

        # point accelerations: a_pt = AF F + AT tau + c   (body frame)
        e = d - self.com
        ex = _skew(e)                                                      # (P, 3, 3)
        iw = self.inertia @ w
        gyro = _cross(w, iw)
        af = np.eye(3) / self.mass.mass + ex @ (self.inertia_inv @ _skew(self.com))
        at = -ex @ self.inertia_inv
        c = ex @ (self.inertia_inv @ gyro) + _cross(w, _cross(w, e))   # (P, 3)
        normals = np.concatenate([r, -r], axis=0)                          # (6, 3): n_b rows
        rows_f = np.einsum("fi,pij->pfj", normals, af)                     # (P, 6, 3)
        rows_t = np.einsum("fi,pij->pfj", normals, at)
        lower = need - np.einsum("fi,pi->pf", normals, c)                  # (P, 6)
        w_row_f, w_row_t, w_lower = self._rate_row(w, gyro)
        wb = self.omega_max ** 2 - float(w @ w) if self.omega_max > 0 else float("inf")

        # transparent when the (clipped) nominal wrench meets every barrier row
        f_c = np.clip(f_nom, -self.f_max, self.f_max)
        t_c = np.clip(t_nom, -self.t_max, self.t_max)
        lhs = rows_f @ f_c + rows_t @ t_c
        if np.all(lhs >= lower) and w_row_f @ f_c + w_row_t @ t_c >= w_lower:
            return SafetyResult(f_c, t_c, False, True, False,
                                float(np.linalg.norm(np.r_[f_c - f_nom, t_c - t_nom])), 0.0,
                                h, h1, sel, omega_barrier=wb)

        # QP: update values only
        nr = 6 * n_pts
        a = self._a
        ab = max(self.a_brake, 1e-9)
        inv_ab = 1.0 / ab
        sc = self._scale
        lo, up = self._l, self._u
        w_scale = 2.0 * self.omega_max * self.alpha_brake
        if w_scale > 0:
            a[7, 0:3] = w_row_f * sc[:3] / w_scale
            a[7, 3:6] = w_row_t * sc[3:] / w_scale
            a[7, 6] = 1.0
            lo[7] = w_lower / w_scale
        else:
            a[7, :] = 0.0
            lo[7] = -INF
        a[8:8 + nr, 0:3] = rows_f.reshape(nr, 3) * (sc[:3] * inv_ab)
        a[8:8 + nr, 3:6] = rows_t.reshape(nr, 3) * (sc[3:] * inv_ab)
        a[8:8 + nr, 6] = 1.0
        a[8 + nr:, :] = 0.0
        lo[:6] = -1.0
        up[:6] = 1.0
        lo[8:8 + nr] = lower.reshape(nr) * inv_ab
        # rows no wrench within the limits can violate are left out (exactly: a row's least
        # value over the bounds is -sum |coefficient|): fewer near-duplicate rows for ADMM
        rows = a[7:8 + nr, :6]
        never = -np.abs(rows).sum(axis=1) >= lo[7:8 + nr]
        lo[7:8 + nr][never] = -INF
        lo[8 + nr:] = -INF
        qv = np.concatenate([-2.0 * np.r_[f_nom, t_nom] / sc, [SLACK_LIN]])
        s = self._solver
        s.update(q=qv, l=lo, u=up, Ax=a.ravel(order="F"))
        res = s.solve(raise_error=False)
        status = str(res.info.status)
        x = res.x
        ok = status.startswith("solved") and x is not None and np.all(np.isfinite(x))
        slack = float(x[6]) if ok else float("inf")
        if not ok or slack > self.slack_tol:
            why = (f"QP {status}" if not ok else
                   f"barriers infeasible within the limits (slack {slack:.3g} braking decelerations)")
            res = self._brake(f_nom, t_nom, vel, w, r, h, h1, sel, slack if ok else float("inf"), why)
            res.omega_barrier = wb
            return res
        f = np.clip(x[0:3], -1.0, 1.0) * self._scale[:3]
        t = np.clip(x[3:6], -1.0, 1.0) * self._scale[3:]
        return SafetyResult(f, t, True, True, False,
                            float(np.linalg.norm(np.r_[f - f_nom, t - t_nom])), max(slack, 0.0),
                            h, h1, sel, omega_barrier=wb)

    def _rate_row(self, w: np.ndarray, gyro: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """The angular-rate barrier as row_f . F + row_t . tau >= lower (body frame):
        -2 w . alpha + k_omega (w_max^2 - |w|^2) >= 0 with alpha = I^-1 (tau - c x F - w x I w).
        No limit (flight mode off): a row that always holds."""
        if self.omega_max <= 0:
            return np.zeros(3), np.zeros(3), -INF
        wi = self.inertia_inv.T @ w                          # w . I^-1 v == wi . v
        h = self.omega_max ** 2 - float(w @ w)
        row_t = -2.0 * wi
        row_f = 2.0 * (wi @ _skew(self.com))                 # +2 wi . (c x F)
        return row_f, row_t, -self.k_omega * h - 2.0 * float(wi @ gyro)

    def braking_wrench(self, velocity: np.ndarray, omega: np.ndarray,
                       orientation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Largest body force opposing the world velocity and torque opposing the body angular
        velocity, each scaled (direction kept) to the per-axis limits."""
        r = _matrix(np.asarray(orientation, float))
        return (_opposing(r.T @ np.asarray(velocity, float), self.f_max),
                _opposing(np.asarray(omega, float), self.t_max))

    def _brake(self, f_nom, t_nom, vel, w, r, h, h1, sel, slack, why) -> SafetyResult:
        f = _opposing(r.T @ vel, self.f_max)
        t = _opposing(w, self.t_max)
        return SafetyResult(f, t, True, False, True,
                            float(np.linalg.norm(np.r_[f - f_nom, t - t_nom])), slack,
                            h, h1, sel, reason=f"fallback to maximum braking: {why}")


def _opposing(v: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """-v scaled so its largest component ratio reaches the per-axis limit (0 for v ~ 0)."""
    mag = np.abs(v)
    if not np.any(mag > 1e-12):
        return np.zeros(3)
    scale = float(np.min(np.where(mag > 1e-12, limit / np.maximum(mag, 1e-300), np.inf)))
    return -v * scale
