"""The predictive controller over the wrench: a linear MPC on the reduced pair model, on OSQP.

Every `replan_period` seconds while a segment is followed, one QP (real-time iteration: the
pair model linearised at the present attitude and at the previous plan's progress,
pair_linear.py) chooses the body-wrench sequence over `horizon` seconds (`steps` steps):

  min  sum_k  w_position |p_k - p_nom(s_k)|^2 + w_velocity |v_k - sigma_k v_nom|^2
              + w_attitude |delta_k - delta_nom|^2 + w_rate |w_k|^2
              + w_swing |phi_k|^2 + w_swing_rate |phi'_k|^2 + w_effort |u_k / limits|^2
              + w_progress (1 - sigma_k)^2 (steps before the nominal's end) - 0.1 w_progress s_k
              + w_slack (corridor slacks)
  s.t. the linear pair model (swing, propulsion lag), per-axis wrench limits, 0 <= sigma <= 1,
       s_k <= segment end; robot and bag centres in time-varying keep-in boxes (the box, or
       two abutting boxes merged at a hatch, each holds along the nominal, shrunk by the robot's
       half size / the bag's extent; soft: an L1 slack); when the horizon reaches the goal, a
       terminal set at rest (|v|, |w|, |phi'| small; soft).

p is the pair's centre of mass, the nominal's moved by the known bag offset. The progress s
runs on the nominal's clock at rate sigma: a disturbed flight slows, pauses or re-times
instead of chasing the clock (no delay budget: the cost of progress trades it off). The
chosen plan becomes the pair law's reference (predicted robot pose, with the planned wrench as
feed-forward, held over each step) followed by the rest of the nominal shifted by the delay; the
pair law (pair_law.py) tracks it at 62.5 Hz between decisions. Warm start: the previous
solution, shifted. Why a QP and not MPPI over wrench splines: the model is nearly linear at the
speeds flown (0.2 m/s, attitude re-linearised every 0.2 s), the corridor and the limits are
exact constraints instead of penalties a sampler may miss, and one OSQP solve of ~700 variables
takes a few ms (bench/pair_control_bench.py) where a sampler needs hundreds of rollouts.
"""
from __future__ import annotations


import numpy as np

from astrobee import rotations as rot
from astrobee.flight_modes import FlightMode

from .law import config_parameters
from . import pair_linear as pl
from .mass import MassProperties
from .pair_law import PARAMETERS as PAIR_PARAMETERS
from .pair_law import PairConfig, PairLaw
from .pair_law import check_params as check_pair
from .pd import State
from .reference import SampledTrajectory
from .registry import Controller
from .tracking import CONTROLLING
from .wrench_qp import Plan, WrenchMpc, WrenchMpcConfig


class WrenchMpcLaw(PairLaw):
    """The wrench MPC as a ControlLaw: decides every replan_period while a segment is followed;
    the pair law (the parent) tracks the chosen plan between decisions and does the rest of the
    state machine (stop, hold, results) as PD's."""

    name = "wmpc"

    def __init__(self, flight_mode: FlightMode, mass: MassProperties,
                 pair_config: PairConfig | None = None,
                 config: WrenchMpcConfig | None = None, keep_in: np.ndarray | None = None,
                 hold_on_start: bool = True) -> None:
        super().__init__(flight_mode, mass, pair_config, hold_on_start)
        self.mpc = WrenchMpc(config or WrenchMpcConfig(), _limits(flight_mode), keep_in)
        self.nominal: SampledTrajectory | None = None
        self.plan: Plan | None = None
        self.decide_s: list[float] = []      # wall seconds per decision (bench)
        self._next = 0.0
        self._finishing = False
        self._last_wrench = np.zeros(6)

    def set_flight_mode(self, mode: FlightMode) -> None:
        super().set_flight_mode(mode)
        self.mpc.limits = _limits(mode)

    def follow(self, traj: SampledTrajectory, now: float) -> None:
        if traj.start_time < now:
            traj = traj.shifted(now - traj.start_time)
        self.nominal = traj
        self.plan = None
        self.mpc.reset()
        self._next = now
        self._finishing = False
        super().follow(traj, now)

    def stop(self, state: State, now: float, why: str = "stop requested") -> None:
        self.nominal = None
        super().stop(state, now, why)

    def rehold(self, state: State, why: str) -> None:
        self.nominal = None
        super().rehold(state, why)

    def predicted_path(self) -> np.ndarray | None:
        """(K, 3) the robot centres the last plan predicts (world), None without one."""
        return None if self.plan is None else self.plan.robot

    def update(self, state: State, now: float, dt: float):
        """One tick: decide when due, then the pair law's step on the chosen plan."""
        if (self.state == CONTROLLING and self.nominal is not None and not self._finishing
                and now >= self._next):
            import time
            self._next = now + self.mpc.config.replan_period
            c0 = time.perf_counter()
            plan = self.decide(state, now)
            self.decide_s.append(time.perf_counter() - c0)
            if plan is not None:
                self.plan = plan
                self.traj = self._executed(plan, now)
        step = super().update(state, now, dt)
        self._last_wrench = np.concatenate([step.output.force, step.output.torque])
        if self.plan is not None and step.chosen is None:
            step.chosen = self.plan.robot
        return step

    def progress(self, now: float) -> float:
        """Where on the nominal's clock the flight is now (the last plan's progress)."""
        if self.plan is None or not self.mpc.config.retime:
            return float(min(now - self._shift0(), self.nominal.end_time))
        return float(np.interp(now, self.plan.t, self.plan.x[:, 18]))

    def _shift0(self) -> float:
        return 0.0

    def state_vector(self, state: State, now: float) -> tuple[np.ndarray, pl.PairFigures]:
        """x0 (pair_linear's state) from the measured robot, the observed bag and the plan's
        progress; with the model's figures."""
        ctl = self.pd
        pair = ctl.pair()
        cfg_p, cfg = ctl.config, self.mpc.config
        g = np.asarray(cfg_p.grasp, float)
        fig = pl.PairFigures(pair.mass, pair.bag_mass, pair.inertia, pair.lever, pair.centre,
                             pair.offset, g if pair.bag_mass > 0 else np.zeros(3),
                             _bag_inertia(ctl), np.asarray(cfg.swing_stiffness, float),
                             np.asarray(cfg.swing_damping, float), cfg.lag)
        R = rot.to_matrix(rot.normalize(state.orientation))
        x0 = np.zeros(pl.NX)
        p, v = np.asarray(state.position, float), np.asarray(state.velocity, float)
        w = np.asarray(state.omega, float)
        x0[pl.W] = w
        if ctl.bag is not None and pair.bag_mass > 0:
            pb, vb = np.asarray(ctl.bag.position, float), np.asarray(ctl.bag.velocity, float)
            arm = R @ pair.centre                   # the centre as held (the pair law's)
            x0[pl.P] = p + arm
            x0[pl.V] = v + np.cross(R @ w, arm)
            l0 = pair.offset - g
            r = R.T @ (pb - p) - g
            rd = R.T @ (vb - v) - np.cross(w, r + g)
            L2 = float(l0 @ l0)
            x0[pl.PHI] = np.cross(l0, r - l0) / L2
            x0[pl.PHID] = np.cross(l0, rd) / L2
        else:
            x0[pl.P], x0[pl.V] = p, v
        x0[18] = self.progress(now)
        x0[pl.LAG] = self._last_wrench
        return x0, fig

    def decide(self, state: State, now: float) -> Plan | None:
        """One QP from the present state (None when nothing is left to plan)."""
        nom = self.nominal
        x0, fig = self.state_vector(state, now)
        if x0[18] >= nom.end_time - 1e-6 and self.plan is not None:
            return None
        R = rot.to_matrix(rot.normalize(state.orientation))
        half = np.zeros(3)
        if self.pd.bag is not None:
            Rb = R @ self.pd.bag_rotation
            half = np.abs(Rb) @ (np.asarray(self.pd.bag.size, float) / 2)
        return self.mpc.decide(now, x0, R, fig, nom, half)

    def _feed_forward(self, plan: Plan, Rk: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(acc, alpha) world, per knot: the accelerations of the pair's centre and attitude that
        the plan's own wrench gives (M a = F, I alpha = tau - lever x F about the centre, the
        pair law's allocation), so the pair law applies the planned wrench; not differences of
        the predicted states (those blend adjacent steps and carry the model's lag and the
        swing's reaction, which the law must not apply again)."""
        pair = self.pd.pair()
        n = len(Rk)
        u = plan.u[np.minimum(np.arange(n), len(plan.u) - 1)]
        F, tau = u[:, :3], u[:, 3:6]
        a_body = F / pair.mass
        al_body = np.linalg.solve(pair.inertia, (tau - np.cross(pair.lever, F)).T).T
        return (np.einsum("kij,kj->ki", Rk, a_body), np.einsum("kij,kj->ki", Rk, al_body))

    def _executed(self, plan: Plan, now: float) -> SampledTrajectory:
        """The plan as the robot's reference (pose, rate, the planned accelerations as
        feed-forward), then the rest of the nominal shifted by the delay; ends at the goal."""
        nom = self.nominal
        X, t = plan.x, plan.t
        c = self.pd.pair().centre
        s = X[:, 18]
        end = int(np.argmax(s >= nom.end_time - 1e-3)) if np.any(s >= nom.end_time - 1e-3) \
            else len(t) - 1
        k = slice(0, end + 1)
        Rk = plan.R0 @ _exp_batch(X[k, 6:9])
        wk = np.einsum("kij,kj->ki", Rk, X[k, 9:12])
        arm = Rk @ c
        pos = X[k, 0:3] - arm
        vel = X[k, 3:6] - np.cross(wk, arm)
        dtp = float(t[1] - t[0])
        acc, alpha = self._feed_forward(plan, Rk)
        q = rot.from_matrix(Rk)
        # each step's feed-forward held over the step (a knot just before the next one): the
        # plan's wrench is piecewise constant, interpolating it would blend steps of opposite sign
        head = [t[k], pos, vel, acc, q, wk, alpha]
        if end > 0:
            eps = 1e-3 * dtp
            pre = [t[1:end + 1] - eps, pos[1:] - vel[1:] * eps, vel[1:] - acc[:-1] * eps,
                   acc[:-1], q[1:], wk[1:], alpha[:-1]]
            order = np.argsort(np.concatenate([t[k], pre[0]]), kind="stable")
            head = [np.concatenate([a, b])[order] for a, b in zip(head, pre)]
        if s[end] >= nom.end_time - 1e-3:
            if end + 1 - 0 <= 1 or t[end] - now < self.mpc.config.replan_period:
                self._finishing = True
            fin = nom.final()
            z = np.zeros((1, 3))
            tail = [np.array([t[end] + dtp]), fin.position[None], z, z,
                    fin.orientation[None], z, z]
        else:
            after = nom.t > s[end] + 1e-6
            sh = t[end] - s[end]
            tail = [nom.t[after] + sh, nom.position[after], nom.velocity[after],
                    nom.accel[after], nom.orientation[after], nom.omega[after],
                    nom.alpha[after]]
        return SampledTrajectory(*(np.concatenate([a, b]) for a, b in zip(head, tail)))


def _limits(mode: FlightMode) -> np.ndarray:
    return np.concatenate([np.asarray(mode.max_force, float), np.asarray(mode.max_torque, float)])


def _bag_inertia(ctl) -> np.ndarray:
    from .mass import box_inertia
    if ctl.bag is None:
        return np.ones(3)
    Rb = ctl.bag_rotation
    return np.diag(Rb @ box_inertia(float(ctl.bag.mass), ctl.bag.size) @ Rb.T).copy()


def _exp_batch(v: np.ndarray) -> np.ndarray:
    from .reduced_model import _exp_so3
    return _exp_so3(np.asarray(v, float))


# the wrench MPC's parameters beyond every controller's (name -> default): its own (one owner:
# WrenchMpcConfig) and the pair law's (the tracking law between decisions)
PARAMETERS = {**PAIR_PARAMETERS, **config_parameters(WrenchMpcConfig())}


def check_params(params: dict) -> None:
    """The wrench MPC's parameters (complete), checked without building it."""
    check_pair(params)
    WrenchMpcConfig.from_params(params)


def make_wrench_mpc_law(flight_mode: FlightMode, mass: MassProperties,
                        params: dict) -> WrenchMpcLaw:
    """The wrench MPC law of the parameters (its own and the pair law's; ValueError with one
    line for a bad value)."""
    params = {**PARAMETERS, **params}
    check_params(params)
    return WrenchMpcLaw(flight_mode, mass, PairConfig.from_params(params),
                        WrenchMpcConfig.from_params(params),
                        hold_on_start=bool(params["hold_on_start"]))


# the registry entry (astrobee_control.registry; pyproject's astrobee.controllers group)
CONTROLLER = Controller("wmpc", make_wrench_mpc_law, PARAMETERS, check_params,
                        "predictive control over the body wrench (QP on the reduced pair "
                        "model, corridor boxes, re-timing) with the pair law tracking")
