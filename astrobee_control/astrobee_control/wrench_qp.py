"""The wrench MPC's quadratic program (wrench_mpc.py's module docstring): the pair model
linearised at the present attitude (pair_linear.py), the cost and constraints assembled as
sparse matrices (the model's blocks cached while its figures hold), one OSQP solve,
warm-started from the previous solution shifted; the inputs rolled out through the model so the
plan's states match its wrenches even when the solver stops at its iteration limit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
import scipy.sparse as sp

from astrobee import rotations as rot

from . import pair_linear as pl
from .reference import SampledTrajectory


@dataclass
class WrenchMpcConfig:
    """The wrench MPC's parameters beyond the pair law's (also the node's ROS parameters)."""

    horizon: float = 6.0             # s
    steps: int = 20                  # QP steps over the horizon
    replan_period: float = 0.2       # s (5 Hz)
    w_position: float = 10.0         # per m^2
    w_velocity: float = 1.0          # per (m/s)^2
    w_attitude: float = 200.0        # per rad^2 (20: seed 3 of the bump check 1012 contact samples,
                                     # 200: none; seed 0 no better)
    w_rate: float = 50.0             # per (rad/s)^2
    w_swing: float = 0.0             # per rad^2 (0: a strap bag sags to new rests the model
                                     # would chase; measured: seed 0 contacts 118 -> 12)
    w_swing_rate: float = 20.0       # per (rad/s)^2
    w_effort: float = 0.01           # per (share of the limit)^2
    w_progress: float = 20.0         # per (1 - sigma)^2 per step
    w_slack: float = 1000.0          # per m of corridor violation (L1)
    w_terminal: float = 200.0        # terminal rest, per (m/s)^2 and (rad/s)^2
    robot_half_size: float = 0.16    # m
    margin: float = 0.03             # m inside the keep-in boxes
    swing_stiffness: tuple = (2.0, 0.05, 0.05)   # N m/rad per body axis (pair_model's strap)
    swing_damping: tuple = (0.2, 0.02, 0.02)     # N m s/rad
    lag: float = 0.15                # s, propulsion lag assumed (the astrobee realism preset's)
    retime: bool = True              # the progress variable (False: follow the clock, ablation)
    max_iter: int = 200              # OSQP iterations per decision (warm-started)

    def validate(self) -> "WrenchMpcConfig":
        """Raise ValueError (one line) for a value the MPC cannot run with."""
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("swing_stiffness", "swing_damping"):
                if len(v) != 3 or not all(isinstance(x, (int, float)) and math.isfinite(x)
                                          and x >= 0 for x in v):
                    raise ValueError(f"{f.name} must be three finite numbers >= 0, got {v!r}")
                continue
            if f.name == "retime":
                if not isinstance(v, (bool, np.bool_)):
                    raise ValueError(f"retime must be true or false, got {v!r}")
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v < 0:
                raise ValueError(f"{f.name} must be a finite number >= 0, got {v!r}")
        for name in ("horizon", "replan_period"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0 s, got {getattr(self, name)!r}")
        if int(self.steps) != self.steps or not 2 <= self.steps <= 200:
            raise ValueError(f"steps must be an integer in [2, 200], got {self.steps!r}")
        if int(self.max_iter) != self.max_iter or self.max_iter < 10:
            raise ValueError(f"max_iter must be an integer >= 10, got {self.max_iter!r}")
        if self.replan_period > self.horizon:
            raise ValueError(f"replan_period ({self.replan_period}) must not exceed horizon "
                             f"({self.horizon})")
        self.steps, self.max_iter = int(self.steps), int(self.max_iter)
        return self

    @classmethod
    def from_params(cls, params: dict) -> "WrenchMpcConfig":
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in params.items() if k in names}).validate()


@dataclass
class Plan:
    """One decision: times, predicted states (N+1, 25) from now, inputs (N, 7), and what it
    cost to find."""

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    R0: np.ndarray
    robot: np.ndarray          # (N+1, 3) predicted robot centres
    bag: np.ndarray            # (N+1, 3) predicted bag centres
    slack: float               # m, the largest corridor violation the plan accepts
    status: str


def select_boxes(boxes: np.ndarray, points: np.ndarray) -> np.ndarray:
    """For each point (K, 3), the index of the keep-in box (B, 6) it sits deepest in (or, if
    in none, least outside)."""
    lo, hi = boxes[None, :, :3], boxes[None, :, 3:]
    depth = np.minimum(points[:, None, :] - lo, hi - points[:, None, :]).min(-1)   # (K, B)
    return np.argmax(depth, axis=1)


def junction_boxes(boxes: np.ndarray) -> np.ndarray:
    """The keep-in boxes (B, 6) and every convex box inside the union of two of them: their
    common cross-section across one axis, the union of their extents along it (valid where
    those extents overlap or touch); a body passing a hatch from one module to the next stays
    inside one of these, not inside either module's box."""
    out = [boxes]
    i, j = np.triu_indices(len(boxes), 1)
    a, b = boxes[i], boxes[j]
    inter_lo, inter_hi = np.maximum(a[:, :3], b[:, :3]), np.minimum(a[:, 3:], b[:, 3:])
    for ax in range(3):
        m = np.concatenate([inter_lo, inter_hi], axis=1)
        m[:, ax] = np.minimum(a[:, ax], b[:, ax])
        m[:, 3 + ax] = np.maximum(a[:, 3 + ax], b[:, 3 + ax])
        ok = np.all(inter_hi - inter_lo >= -1e-9, axis=1)
        out.append(m[ok])
    return np.unique(np.concatenate(out), axis=0)


def corridor(boxes: np.ndarray, points: np.ndarray, shrink: np.ndarray | float) -> np.ndarray:
    """For each point (K, 3), the box of `boxes` (junction_boxes' output) the body centred there
    sits deepest in once the box is shrunk by `shrink` (m, scalar or per axis): (K, 6), shrunk."""
    sh = np.broadcast_to(np.asarray(shrink, float), (3,))
    lo, hi = boxes[None, :, :3] + sh, boxes[None, :, 3:] - sh
    depth = np.minimum(points[:, None, :] - lo, hi - points[:, None, :]).min(-1)   # (K, C)
    k = np.argmax(depth, axis=1)
    return np.concatenate([lo[0, k], hi[0, k]], axis=1)


class WrenchMpc:
    """The QP (module docstring) over a PairFigures model; `decide` returns a Plan."""

    def __init__(self, config: WrenchMpcConfig, limits: np.ndarray,
                 keep_in: np.ndarray | None = None) -> None:
        from astrobee import config as cfg
        self.config = config.validate()
        self.limits = np.asarray(limits, float)            # (6,) body wrench limits
        self.boxes = np.asarray(cfg.keep_in_boxes() if keep_in is None else keep_in, float)
        self._junctions: tuple[np.ndarray, np.ndarray] | None = None   # (boxes, their junctions)
        self._warm: tuple[float, np.ndarray] | None = None  # (time, z) of the last solution

    def decide(self, now: float, x0: np.ndarray, R0: np.ndarray, fig: pl.PairFigures,
               nominal: SampledTrajectory, bag_half: np.ndarray) -> Plan:
        """The plan from state x0 (25,; p, v world) at `now`, the nominal's clock at x0[18];
        bag_half (3,) the bag's half extents along the world axes (for its corridor box)."""
        import osqp
        c = self.config
        N, nx, nu = c.steps, pl.NX, pl.NU
        dt = c.horizon / N
        fig = pl.PairFigures(**{**fig.__dict__, "lag": c.lag})
        Ad, Bd = self._discrete(fig, dt)
        Cr, cr, Cb, cb = pl.positions(fig, R0)
        x0 = np.asarray(x0, float).copy()
        x0[pl.P], x0[pl.V] = R0.T @ x0[pl.P], R0.T @ x0[pl.V]     # into R0's frame
        s0, s_end = float(x0[18]), float(nominal.end_time)
        s_bar = self._progress_guess(now, s0, s_end, dt, N)
        ref = [nominal.sample(s) for s in s_bar]
        q_ref = np.array([r.orientation for r in ref])
        R_ref = rot.to_matrix(q_ref)
        robot_nom = np.array([r.position for r in ref])
        p_nom = (robot_nom + R_ref @ fig.centre) @ R0                 # (N, 3) R0 frame
        bag_nom = robot_nom + R_ref @ fig.offset
        v_nom = np.array([r.velocity for r in ref]) @ R0
        d_nom = rot.to_rotvec(rot.from_matrix(R0.T @ R_ref))
        reaches_end = bool(s_bar[-1] >= s_end - 1e-6)
        nz = N * nx + N * nu + 2 * N + 1
        ku = N * nx                                   # first input
        ie = N * nx + N * nu                          # first slack
        kx = np.arange(N) * nx                        # x_{k+1} offsets
        ks = kx + 18                                  # progress s_{k+1}
        ksig = ku + np.arange(N) * nu + 6             # sigma_k
        rows, cols, vals = [], [], []
        q = np.zeros(nz)

        def add(r, cidx, v):
            rows.append(np.ravel(r)), cols.append(np.ravel(cidx)), vals.append(np.ravel(v))

        def pair_term(a_idx, b_idx, coef_b, target, w):
            """w (z_a + coef_b z_b - target)^2 (arrays over (N, 3))."""
            add(a_idx, a_idx, 2 * w * np.ones_like(coef_b))
            add(a_idx, b_idx, 2 * w * coef_b)
            add(b_idx, a_idx, 2 * w * coef_b)
            add(b_idx, b_idx, 2 * w * coef_b ** 2)
            np.add.at(q, np.ravel(a_idx), np.ravel(-2 * w * target))
            np.add.at(q, np.ravel(b_idx), np.ravel(-2 * w * coef_b * target))

        def diag_term(idx, target, w):
            add(idx, idx, 2 * w * np.ones(np.shape(idx)))
            np.add.at(q, np.ravel(idx), np.ravel(-2 * w * np.broadcast_to(target, np.shape(idx))))

        ax3 = np.arange(3)
        end_w = np.zeros(N)
        if reaches_end:
            end_w[-1] = c.w_terminal
        rt = 1.0 if c.retime else 0.0
        pair_term(kx[:, None] + ax3, np.repeat(ks[:, None], 3, 1), -rt * v_nom,
                  p_nom - rt * v_nom * s_bar[:, None], c.w_position)
        wv = (c.w_velocity + end_w)[:, None] * np.ones(3)
        pair_term(kx[:, None] + 3 + ax3, np.repeat(ksig[:, None], 3, 1), -rt * v_nom,
                  (1 - rt) * v_nom, wv)
        diag_term(kx[:, None] + 6 + ax3, d_nom, c.w_attitude)
        diag_term(kx[:, None] + 9 + ax3, 0.0, (c.w_rate + end_w)[:, None] * np.ones(3))
        diag_term(kx[:, None] + 12 + ax3, 0.0, c.w_swing)
        diag_term(kx[:, None] + 15 + ax3, 0.0, (c.w_swing_rate + end_w)[:, None] * np.ones(3))
        diag_term(ku + np.arange(N)[:, None] * nu + np.arange(6),
                  0.0, c.w_effort / self.limits ** 2)
        # progress is wanted only until the nominal's end: past it sigma is 0 by s <= s_end,
        # and paying (1 - sigma)^2 there spread the rest evenly over the horizon (sigma =
        # remaining / horizon: an exponential approach that never arrived)
        # (the linearisation's progress tells which steps start before the end; a small reward
        # on every step's progress carries the plan on where that guess ended too early)
        starts = np.concatenate([[s0], s_bar[:-1]])
        diag_term(ksig, 1.0, c.w_progress * (starts < s_end - 1e-6))
        q[ks] -= 0.1 * c.w_progress
        diag_term(np.arange(nz), 0.0, 1e-6)
        q[ie:] += c.w_slack
        r_, c_, v_ = (np.concatenate(x) for x in (rows, cols, vals))
        keep = r_ <= c_
        P = sp.csc_matrix((v_[keep], (r_[keep], c_[keep])), shape=(nz, nz))
        # ---- constraints ---------------------------------------------------------------
        I_N = sp.eye(N, format="csc")
        Aeq, Au, As, Ae, Epos = self._static(Ad, Bd, N, nz, ks)
        leq = np.zeros(N * nx)
        leq[:nx] = -Ad @ x0
        lu = np.tile(np.concatenate([-self.limits, [0.0 if c.retime else 1.0]]), N)
        uu = np.tile(np.concatenate([self.limits, [1.0]]), N)
        cands = self._corridor_boxes()
        box_r = corridor(cands, robot_nom, c.robot_half_size + c.margin)
        box_b = corridor(cands, bag_nom, np.asarray(bag_half, float) + c.margin)
        blocks, lo_parts, hi_parts = [], [], []
        for C, off, box, E in ((Cr, cr, box_r, Epos[0]), (Cb, cb, box_b, Epos[1])):
            G = sp.kron(I_N, sp.csc_matrix(C))                          # (3N, N nx)
            G = sp.hstack([G, sp.csc_matrix((3 * N, nz - N * nx))], format="csc")
            blocks += [G + E, G - E]
            lo = (box[:, :3] - off).ravel()
            hi = (box[:, 3:] - off).ravel()
            lo_parts += [lo, np.full(3 * N, -np.inf)]
            hi_parts += [np.full(3 * N, np.inf), hi]
        # terminal rest (soft): |v_N|, |w_N| <= eps + e_term
        tcols = kx[-1] + np.r_[3:6, 9:12]
        T = sp.csc_matrix((np.ones(6), (np.arange(6), tcols)), shape=(6, nz))
        Te = sp.csc_matrix((np.ones(6), (np.arange(6), np.full(6, nz - 1))), shape=(6, nz))
        eps = np.r_[np.full(3, 0.005), np.full(3, 0.01)]
        big = np.inf if not reaches_end else 0.0
        blocks += [T + Te, T - Te]
        lo_parts += [-eps - big, np.full(6, -np.inf)]
        hi_parts += [np.full(6, np.inf), eps + big]
        A = sp.vstack([Aeq, Au, As, *blocks, Ae], format="csc")
        lo = np.concatenate([leq, lu, np.full(N, -np.inf), *lo_parts, np.zeros(2 * N + 1)])
        hi = np.concatenate([leq, uu, np.full(N, s_end), *hi_parts, np.full(2 * N + 1, np.inf)])
        solver = osqp.OSQP()
        solver.setup(P, q, A, lo, hi, verbose=False, warm_starting=True, polishing=False,
                     max_iter=c.max_iter, eps_abs=1e-3, eps_rel=1e-3, adaptive_rho=True)
        if self._warm is not None:
            t_prev, z_prev = self._warm
            solver.warm_start(x=_shifted(z_prev, int(round((now - t_prev) / dt)), N, nx, nu))
        res = solver.solve(raise_error=False)
        z = res.x
        status = str(res.info.status)
        if z is None or not np.all(np.isfinite(z)):
            z = np.zeros(nz)
            status = "failed: " + status
        self._warm = (now, z.copy())
        U = z[ku:ie].reshape(N, nu)
        U[:, :6] = np.clip(U[:, :6], -self.limits, self.limits)
        U[:, 6] = np.clip(U[:, 6], 0.0, 1.0)
        X = np.empty((N + 1, nx))        # the inputs rolled out: states consistent with them
        X[0] = x0                        # even when the solver stopped early
        for k in range(N):
            X[k + 1] = Ad @ X[k] + Bd @ U[k]
        X[:, 18] = np.minimum(X[:, 18], s_end)
        robot = X @ Cr.T + cr
        bag = X @ Cb.T + cb
        X[:, pl.P] = X[:, pl.P] @ R0.T                                  # back to world
        X[:, pl.V] = X[:, pl.V] @ R0.T
        return Plan(now + dt * np.arange(N + 1), X, U, R0, robot, bag,
                    float(np.max(z[ie:])), status)

    def _corridor_boxes(self) -> np.ndarray:
        """junction_boxes of the keep-in boxes, kept while the boxes are the same."""
        if self._junctions is None or self._junctions[0] is not self.boxes:
            self._junctions = (self.boxes, junction_boxes(self.boxes))
        return self._junctions[1]

    def _static(self, Ad: np.ndarray, Bd: np.ndarray, N: int, nz: int, ks: np.ndarray) -> tuple:
        """The constraint blocks that change only with the model: dynamics, input boxes,
        progress bound, slack signs and the slacks' columns of the corridor rows."""
        key = (id(Ad), N, nz)
        if getattr(self, "_static_key", None) == key:
            return self._static_blocks
        nx, nu = pl.NX, pl.NU
        ie = N * nx + N * nu
        I_N = sp.eye(N, format="csc")
        Ax = -sp.eye(N * nx, format="csc") + sp.kron(sp.eye(N, k=-1), sp.csc_matrix(Ad))
        Aeq = sp.hstack([Ax, sp.kron(I_N, sp.csc_matrix(Bd)),
                         sp.csc_matrix((N * nx, 2 * N + 1))], format="csc")
        Au = sp.hstack([sp.csc_matrix((N * nu, N * nx)), sp.eye(N * nu),
                        sp.csc_matrix((N * nu, 2 * N + 1))], format="csc")
        As = sp.csc_matrix((np.ones(N), (np.arange(N), ks)), shape=(N, nz))
        Ae = sp.hstack([sp.csc_matrix((2 * N + 1, ie)), sp.eye(2 * N + 1)], format="csc")
        rows = np.arange(3 * N)
        Epos = [sp.csc_matrix((np.ones(3 * N), (rows, first + rows // 3)), shape=(3 * N, nz))
                for first in (ie, ie + N)]
        self._static_key = key
        self._static_blocks = (Aeq, Au, As, Ae, Epos)
        return self._static_blocks

    def _discrete(self, fig: pl.PairFigures, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """pair_linear.discrete, cached while the figures stay within a mm / 1% of the last."""
        key = np.concatenate([[fig.mass, fig.bag_mass, fig.lag, dt], fig.inertia.ravel(),
                              fig.lever, fig.offset, fig.grasp, fig.bag_inertia,
                              fig.swing_stiffness, fig.swing_damping])
        cached = getattr(self, "_disc", None)
        if cached is None or cached[0].shape != key.shape or \
                np.any(np.abs(cached[0] - key) > 1e-3 + 1e-2 * np.abs(key)):
            self._disc = (key, *pl.discrete(fig, dt))
        return self._disc[1], self._disc[2]

    def _progress_guess(self, now: float, s0: float, s_end: float, dt: float,
                        N: int) -> np.ndarray:
        """The progress the linearisation is taken at: the previous plan's rates, shifted
        (the clock's without one or without re-timing)."""
        sig = np.ones(N)
        if self._warm is not None and self.config.retime:
            t_prev, z_prev = self._warm
            prev = z_prev[N * pl.NX + 6:N * (pl.NX + pl.NU):pl.NU]
            sh = min(max(int(round((now - t_prev) / dt)), 0), N)
            sig = np.concatenate([prev[sh:], np.full(sh, prev[-1])])
        return np.minimum(s0 + dt * np.cumsum(np.clip(sig, 0.2, 1.0)), s_end)

    def reset(self) -> None:
        self._warm = None


def _shifted(z: np.ndarray, shift: int, N: int, nx: int, nu: int) -> np.ndarray:
    """The previous solution moved `shift` steps earlier (the last step repeated)."""
    if shift <= 0:
        return z
    X = z[:N * nx].reshape(N, nx)
    U = z[N * nx:N * nx + N * nu].reshape(N, nu)
    s = min(shift, N - 1)
    X = np.vstack([X[s:], np.repeat(X[-1:], s, 0)])
    U = np.vstack([U[s:], np.repeat(U[-1:], s, 0)])
    return np.concatenate([X.ravel(), U.ravel(), z[N * (nx + nu):]])


def _log(Rm: np.ndarray) -> np.ndarray:
    """Rotation vector of a rotation matrix."""
    return rot.to_rotvec(rot.from_matrix(Rm))
