"""The sampling MPC ControlLaw (the paper's algorithm, with a closed-form rollout model).

Every `replan_period` seconds while a segment is being followed:
1. take the nominal reference at the horizon's end t_h = min(now + horizon, segment end) and
   sample N targets around it (position and velocity perturbed; candidate 0 is the nominal
   target itself, candidate 1 the previous best perturbation: the warm start; half the rest
   are drawn around zero, half around the warm start). Perturbations shrink to zero as t_h
   reaches the segment's end, so the goal is never moved;
2. turn each target into a candidate reference from the current state with the batched local
   planner (astrobee_planning.local_planner.control_points: one quintic per candidate);
3. roll every candidate out with the PD law on a rollout model (reduced_model.RolloutModel:
   model A closed-form, or the pybullet model B) for the whole horizon, all N at once;
4. score each (tracking error to the nominal, clearance of robot AND bag corners to the keep-in
   union with a collision penalty, effort, bag-robot relative speed) and execute the best: the
   law's Tracker (tracking.Tracker, the PD law's state machine) is handed the chosen candidate
   followed by the rest of the nominal, so CONTROLLING/STOPPING/STOPPED, stop, rehold and
   segment_result behave exactly as with the PD law.

Attitude follows the nominal segment (the candidates perturb translation only), so all
candidates share one rotation per rollout step.

Attitude-aware mode (`attitude: true`; the controller study found the translation-only MPC fails
where PD does: a bump on the bag spins robot + bag, and the flight mode's torque limits, fought
by the position loop's off-centre force, do not take the spin back before the segment ends).
With the turning rollout model (robot + bag one rigid body, ReducedModel.turns) each decision
also varies, per candidate:
- the translation's progress (time scaling): a candidate follows the nominal at rate s in
  {1, (1 + time_scale_min)/2, time_scale_min} (0: pause), so the position loop stops asking
  for the off-centre force that turns the pair while the attitude is being recovered; the
  delay is booked (at most `max_delay` s in all: the task allows plan + settle + 10 s) and the
  rest of the nominal is shifted by it. At the segment's end a pair still turning or off the
  final attitude is held at the goal one replan period more (the pause candidate, by rule,
  within the same budget): the torque-limited attitude gets that time before the settle time;
- the attitude reference: `attitude_share` of the candidates get a recovery profile instead of
  the nominal attitude, q_ref(t) = q_nom(t) exp(delta(t)), delta a quintic (per body axis) from
  the present attitude offset (at the nominal's rate: re-anchored each replan at the measured
  rate it let a spin run on) to zero in Tc seconds; Tc is drawn between the shortest recovery
  whose feed-forward torque I_c delta'' (I_c: the pair's inertia about its centre of mass)
  stays within `torque_margin` of the flight mode's torque limits and 2.5x it; its position
  reference is shifted by (R_nom - R_ref) c so the pair turns about its centre of mass.
The cost adds, from the rollout's own attitude dynamics: the mean squared attitude error to
the (time-scaled) nominal attitude (`w_attitude`), the squared angular momentum of the pair
about its centre at the horizon's end (`w_momentum`), the delay (`w_delay`, per s) and the
collision weight for a candidate more than `max_deviation` from the nominal path; the nominal
candidate is left only for `min_gain` less cost (the model is coarse: its choices among
candidates it scores alike are noise). Without a bag or with a model that does not turn, the
decision is the translation-only one. Measured (studies/mpc_attitude_study.yaml): see README.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np

from astrobee import rotations as rot
from astrobee.flight_modes import FlightMode
from astrobee_planning import bezier
from astrobee_planning.local_planner import control_points

from .clearance import KeepIn
from .law import BagObservation, Step
from .mass import MassProperties
from .pd import State
from .reduced_model import (CandidateReferences, Gains, RolloutModel, RolloutStart,
                            _exp_so3, _log_so3, compound_inertia, rotate_by)
from .reference import SampledTrajectory
from .registry import Controller
from .tracking import CONTROLLING, SETTLE_TIME, Tracker, check_settle_time

MODELS = ("reduced", "pybullet")
HOLD_OMEGA = 0.02    # rad/s: below it (and near the final attitude) the pair is not held longer
_CUBE = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)


@dataclass
class MpcConfig:
    """The MPC's parameters (also the node's ROS parameters of the same names)."""

    samples: int = 128
    horizon: float = 5.0             # s
    replan_period: float = 1.0       # s of a chosen candidate executed before replanning
    rollout_dt: float = 0.04         # s, rollout step
    cost_stride: int = 5             # clearance checked every cost_stride rollout steps
    sigma_position: float = 0.15     # m, target perturbation (1 sigma per axis)
    sigma_velocity: float = 0.03     # m/s
    w_track: float = 10.0            # per m^2 of mean squared tracking error
    w_collision: float = 1000.0      # once per candidate whose robot or bag leaves the union
    w_clearance: float = 1000.0      # per m^2 of mean squared intrusion into the margin
    clearance_margin: float = 0.05   # m
    w_effort: float = 0.1            # per N^2 of mean squared force
    w_relvel: float = 10.0           # per (m/s)^2 of mean squared bag-robot relative speed
    robot_half_size: float = 0.16    # m, half the robot's envelope (its corners are checked)
    seed: int = 0
    # attitude-aware mode (module docstring): attitude candidates, time scaling, attitude cost
    attitude: bool = False
    attitude_share: float = 0.5      # share of candidates with a recovery attitude reference
    torque_margin: float = 0.7       # recovery feed-forward within this share of torque limits
    time_scale_min: float = 0.0      # slowest translation progress of a candidate (0: pause)
    max_delay: float = 8.0           # s the segment may be delayed in all
    w_attitude: float = 20.0         # per rad^2 of mean squared attitude error to the nominal
    w_momentum: float = 200.0        # per (N m s)^2 of the pair's angular momentum at the end
    w_delay: float = 0.5             # per s of translation delay over the horizon
    max_deviation: float = 0.3       # m from the (time-scaled) nominal; beyond: w_collision
    min_gain: float = 0.1            # leave the nominal candidate only for this share less cost
    hold_about_centre: bool = False  # the end-of-segment hold lets the pair turn about its centre

    def validate(self) -> "MpcConfig":
        """Raise ValueError (one line) for a value the MPC cannot run with."""
        if int(self.samples) != self.samples or self.samples <= 0:
            raise ValueError(f"samples must be a positive integer, got {self.samples!r}")
        for name in ("horizon", "replan_period", "rollout_dt"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number of seconds, got {v!r}")
        if self.replan_period > self.horizon:
            raise ValueError(f"replan_period ({self.replan_period}) must not exceed horizon "
                             f"({self.horizon})")
        if self.rollout_dt > self.horizon / 2:
            raise ValueError(f"rollout_dt ({self.rollout_dt}) must be at most half the horizon")
        if int(self.cost_stride) != self.cost_stride or self.cost_stride <= 0:
            raise ValueError(f"cost_stride must be a positive integer, got {self.cost_stride!r}")
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name.startswith(("w_", "sigma_")) or f.name in ("clearance_margin",
                                                                 "robot_half_size"):
                if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                    raise ValueError(f"{f.name} must be a finite number >= 0, got {v!r}")
        for name, lo, hi in (("attitude_share", 0.0, 1.0), ("torque_margin", 1e-3, 1.0),
                             ("max_deviation", 0.0, 10.0), ("min_gain", 0.0, 1.0),
                             ("time_scale_min", 0.0, 1.0), ("max_delay", 0.0, 60.0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"{name} must be a number in [{lo:g}, {hi:g}], got {v!r}")
        self.samples, self.cost_stride = int(self.samples), int(self.cost_stride)
        self.attitude, self.hold_about_centre = bool(self.attitude), bool(self.hold_about_centre)
        return self

    @classmethod
    def from_params(cls, params: dict) -> "MpcConfig":
        """From a parameter dict (unknown keys ignored), validated."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in params.items() if k in names}).validate()


@dataclass
class Decision:
    """One replan: what was considered and what was chosen."""

    time: float
    targets: np.ndarray          # (N, 3) candidate end positions
    costs: np.ndarray            # (N,)
    clearance: np.ndarray        # (N,) smallest robot/bag clearance over the horizon (m)
    best: int
    candidates: np.ndarray       # (N, K, 3) rolled-out robot positions (display)
    chosen: np.ndarray           # (K, 3)
    executed: SampledTrajectory  # chosen candidate, then the rest of the nominal
    attitude_error: np.ndarray | None = None  # (N,) rad at the horizon's end (attitude mode)
    delay: np.ndarray | None = None           # (N,) s of translation delay (attitude mode)


class MpcLaw:
    """Sampling MPC over a rollout model; a ControlLaw (law.py)."""

    name = "mpc"

    def __init__(self, flight_mode: FlightMode, mass: MassProperties, model: RolloutModel,
                 config: MpcConfig | None = None, keep_in: np.ndarray | None = None,
                 settle_time: float = SETTLE_TIME) -> None:
        from astrobee import config as cfg
        self.config = (config or MpcConfig()).validate()
        self.model = model
        self.tracker = Tracker(flight_mode, mass, settle_time=settle_time)
        self.keep_in = KeepIn(cfg.keep_in_boxes() if keep_in is None else keep_in)
        self.rng = np.random.default_rng(self.config.seed)
        self.nominal: SampledTrajectory | None = None
        self.bag: BagObservation | None = None
        self.rest_offset: np.ndarray | None = None
        self.bag_rotation = np.eye(3)
        self.last: Decision | None = None
        self._next_replan = 0.0
        self._warm: np.ndarray | None = None   # (6,) previous best [dp, dv]
        self._delay = 0.0                      # s the translation lags the nominal (attitude mode)
        self._goal = None                      # the final pose while held at the goal
        self._hold_end = 0.0
        self._centre = np.zeros(3)

    # ---- ControlLaw plumbing: the Tracker's state machine -------------------------------
    @property
    def state(self) -> int:
        return self.tracker.state

    @property
    def segment_result(self) -> str:
        return self.tracker.segment_result

    @property
    def flight_mode(self) -> FlightMode:
        return self.tracker.flight_mode

    def set_flight_mode(self, mode: FlightMode) -> None:
        self.tracker.set_flight_mode(mode)

    def set_mass(self, mass: MassProperties) -> None:
        self.tracker.set_mass(mass)

    def observe_bag(self, bag: BagObservation | None, robot: State | None) -> None:
        """Mass feed-forward (as PD) plus the bag's state and a slow average of its offset
        (the spring's rest offset: it depends on the handle variant, so it is observed)."""
        self.tracker.observe_bag(bag, robot)
        if bag is None or not bag.attached or robot is None or bag.mass <= 0:
            self.bag, self.rest_offset = None, None
            return
        select = getattr(self.model, "select_bag", None)
        if select is not None and bag.model:
            select(bag.model)
        offset, r_rel = bag.offset_in(robot)
        self.rest_offset = offset if self.rest_offset is None else \
            0.995 * self.rest_offset + 0.005 * offset
        self.bag_rotation = r_rel
        self.bag = bag

    def follow(self, traj: SampledTrajectory, now: float) -> None:
        if traj.start_time < now:
            traj = traj.shifted(now - traj.start_time)
        self.nominal = traj
        self._warm = None
        self._delay = 0.0
        self._goal = None
        self._next_replan = now
        self.tracker.follow(traj, now)

    def stop(self, state: State, now: float, why: str = "stop requested") -> None:
        self.nominal = None
        self.tracker.stop(state, now, why)

    def rehold(self, state: State, why: str) -> None:
        self.nominal = None
        self.tracker.rehold(state, why)

    def update(self, state: State, now: float, dt: float) -> Step:
        """One control tick: replan when due, then the Tracker's PD step on the chosen plan."""
        decision = None
        if (self.tracker.state == CONTROLLING and self.nominal is not None
                and now >= self._next_replan and now < self.nominal.end_time + self._delay):
            self._next_replan = now + self.config.replan_period
            decision = self.decide(state, now)
            if decision is not None:
                self.tracker.traj = decision.executed
                self.last = decision
        self._hold_at_goal(state, now, dt)
        step = self.tracker.update(state, now, dt)
        if decision is not None:
            step.candidates, step.chosen = decision.candidates, decision.chosen
        return step

    def _hold_at_goal(self, state: State, now: float, dt: float) -> None:
        """Attitude mode: the pause candidate at the segment's end. While the pair is still
        turning or off the final attitude when the plan is about to end, hold the final pose
        one replan period more (booked as delay, at most max_delay in all): the torque-limited
        attitude gets that time before the Tracker's settle time starts (the MPC keeps
        deciding meanwhile). With `hold_about_centre` (off: measured worse, see README) the
        held position is instead where the robot is when the pair's centre of mass sits at the
        goal's, re-aimed every tick, so the pair turns about its centre of mass (inertia I_c,
        about half the pair's inertia about the robot) instead of about a pinned robot."""
        c, traj = self.config, self.tracker.traj
        if not (c.attitude and self.tracker.state == CONTROLLING and traj is not None
                and self.nominal is not None and self.bag is not None):
            self._goal = None
            return
        goal = traj.final()
        ends = self._hold_end if (c.hold_about_centre and self._goal is not None) else \
            traj.end_time
        if now + dt >= ends and self._delay + c.replan_period <= c.max_delay + 1e-9:
            off = rot.angle_between(state.orientation, goal.orientation)
            if off > 0.5 * self.flight_mode.tolerance_att or \
                    float(np.linalg.norm(state.omega)) > HOLD_OMEGA:
                self._delay += c.replan_period
                if not c.hold_about_centre:
                    self.tracker.traj = _append_hold(traj, traj.end_time + c.replan_period)
                    return
                if self._goal is None:
                    self._goal, self._hold_end = goal, traj.end_time
                    self._centre = compound_inertia(self._start(state), self._handle_offset())[1]
                self._hold_end += c.replan_period
        if self._goal is None or not c.hold_about_centre or now >= self._hold_end:
            return
        goal = self._goal
        R_now, R_goal = rot.to_matrix(state.orientation), rot.to_matrix(goal.orientation)
        arm = R_now @ self._centre                                  # robot -> centre, world
        p = goal.position + R_goal @ self._centre - arm
        v = -np.cross(R_now @ np.asarray(state.omega, float), arm)
        z = np.zeros(3)
        self.tracker.traj = SampledTrajectory(
            np.array([now, max(self._hold_end, now + 1e-3)]), np.stack([p, p]), np.stack([v, v]),
            np.stack([z, z]), np.stack([goal.orientation, goal.orientation]), np.stack([z, z]),
            np.stack([z, z]))

    # ---- the MPC proper --------------------------------------------------------------------
    def _perturbations(self, n: int, scale: float) -> np.ndarray:
        c = self.config
        sig = np.concatenate([np.full(3, c.sigma_position), np.full(3, c.sigma_velocity)]) * scale
        out = self.rng.normal(size=(n, 6)) * sig
        out[0] = 0.0
        if self._warm is not None and n > 1:
            warm = self._warm * scale
            out[1] = warm
            half = 2 + (n - 2) // 2
            out[half:] += warm
        return out

    def decide(self, state: State, now: float) -> Decision | None:
        """Sample, roll out, score; None when too little of the segment is left to plan."""
        if self.config.attitude and self._turns(state):
            return self._decide_attitude(state, now)
        c, nom = self.config, self.nominal
        t_end = min(now + c.horizon, nom.end_time)
        T = t_end - now
        m = int(math.ceil(T / c.rollout_dt))
        if m < max(2, c.cost_stride):     # fewer steps than one clearance check: nothing to score
            return None
        dt_r = T / m
        scale = float(np.clip((nom.end_time - t_end) / c.horizon, 0.0, 1.0))
        goal = nom.sample(t_end)
        dz = self._perturbations(c.samples, scale)
        p1 = goal.position + dz[:, :3]
        v1 = goal.velocity + dz[:, 3:]
        vmax = self.flight_mode.hard_limit_vel
        speed = np.linalg.norm(v1, axis=1, keepdims=True)
        v1 = np.where(speed > vmax, v1 * (vmax / np.maximum(speed, 1e-12)), v1)
        a0 = self.tracker.traj.sample(now).accel if self.tracker.traj is not None else \
            nom.sample(now).accel
        pts = control_points(state.position, state.velocity, a0, p1, v1, goal.accel, T)
        s = np.arange(m) / m
        ref_p, ref_v, ref_a = _bezier_states(pts, T, s)
        times = now + np.arange(m + 1) * dt_r
        quats = _interp_quat(nom, times)
        rotation = rot.to_matrix(quats)                     # (m+1, 3, 3)
        refs = CandidateReferences(ref_p, ref_v, ref_a, rotation[:m], dt_r)
        start = self._start(state)
        out = self.model.rollout(start, refs, Gains.from_flight_mode(self.flight_mode))
        costs, clearance = self._score(out, nom, times[1:], rotation[1:], start)
        best = int(np.argmin(costs))
        self._warm = dz[best] / scale if scale > 1e-6 else self._warm
        stride = c.cost_stride
        executed = self._executed(pts[best], now, T)
        return Decision(now, p1, costs, clearance, best, out.robot_position[:, ::stride],
                        out.robot_position[best, ::stride], executed)

    def _handle_offset(self) -> np.ndarray:
        """The bag's rest offset from the gripper: the controller's, else the rollout model's."""
        if self.rest_offset is not None:
            return self.rest_offset
        return getattr(self.model.handle, "rest_offset", np.zeros(3))

    def _turns(self, state: State) -> bool:
        """The rollout model integrates robot + bag attitude (attitude mode applies)."""
        turns = getattr(self.model, "turns", None)
        return self.bag is not None and turns is not None and bool(turns(self._start(state)))

    def _decide_attitude(self, state: State, now: float) -> Decision | None:
        """The attitude-aware decision (module docstring): time-scaled translation candidates,
        recovery attitude references, the attitude and angular-momentum cost."""
        c, nom = self.config, self.nominal
        t0n = now - self._delay                              # the nominal's clock now
        T = min(c.horizon, nom.end_time - t0n)
        m = int(math.ceil(T / c.rollout_dt)) if T > 0 else 0
        if m < max(2, c.cost_stride):
            return None
        dt_r, n = T / m, c.samples
        times = now + np.arange(m + 1) * dt_r
        scales = self._time_scales(n)
        tau = t0n + scales[:, None] * (times - now)          # (N, m+1) nominal times
        tau_h = np.minimum(tau[:, -1], nom.end_time)
        pscale = np.clip((nom.end_time - tau_h) / c.horizon, 0.0, 1.0)
        dz = self._perturbations(n, 1.0) * pscale[:, None]
        p_h, v_h, a_h = (_interp(nom.t, x, tau_h) for x in (nom.position, nom.velocity, nom.accel))
        p1 = p_h + dz[:, :3]
        v1 = scales[:, None] * v_h + dz[:, 3:]
        vmax = self.flight_mode.hard_limit_vel
        speed = np.linalg.norm(v1, axis=1, keepdims=True)
        v1 = np.where(speed > vmax, v1 * (vmax / np.maximum(speed, 1e-12)), v1)
        a0 = self.tracker.traj.sample(now).accel if self.tracker.traj is not None else \
            nom.sample(now).accel
        pts = control_points(state.position, state.velocity, a0, p1, v1,
                             scales[:, None] ** 2 * a_h, T)
        ref_p, ref_v, ref_a = _bezier_states(pts, T, np.arange(m) / m)
        start = self._start(state)
        I_c, centre = compound_inertia(start, self._handle_offset())
        plan = attitude_candidates(nom, tau, times - now, state, scales, I_c,
                                   np.asarray(self.flight_mode.max_torque, float), c,
                                   self.rng, n, centre)
        ref_p = ref_p + plan.shift[:, :m]
        ref_v = ref_v + plan.shift_velocity[:, :m]
        ref_a = ref_a + plan.shift_accel[:, :m]
        refs = CandidateReferences(ref_p, ref_v, ref_a, plan.rotation[:, :m], dt_r,
                                   plan.omega[:, :m], plan.alpha[:, :m])
        out = self.model.rollout(start, refs, Gains.from_flight_mode(self.flight_mode))
        costs, clearance, att_end = self._score_attitude(out, nom, tau[:, 1:], plan, start,
                                                         scales, T)
        best = int(np.argmin(costs))
        if costs[best] > (1.0 - c.min_gain) * costs[0]:
            best = 0                     # not worth leaving the nominal (the model is coarse)
        if pscale[best] > 1e-6:          # warm start, kept within 2 sigma (no random walk)
            sig = np.r_[np.full(3, c.sigma_position), np.full(3, c.sigma_velocity)]
            self._warm = np.clip(dz[best] / pscale[best], -2.0 * sig, 2.0 * sig)
        self._delay += (1.0 - scales[best]) * min(c.replan_period, T)
        stride = c.cost_stride
        executed = self._executed_attitude(pts[best], now, T, plan, best, tau_h[best])
        return Decision(now, p1, costs, clearance, best, out.robot_position[:, ::stride],
                        out.robot_position[best, ::stride], executed, att_end,
                        (1.0 - scales) * T)

    def _time_scales(self, n: int) -> np.ndarray:
        """Per candidate, the rate the translation follows the nominal at (candidates 0 and 1,
        the nominal and the warm start, at 1); none may push the delay past max_delay."""
        c = self.config
        out = np.ones(n)
        room = c.max_delay - self._delay
        if n > 2 and room > 1e-6 and c.time_scale_min < 1.0:
            levels = np.array([1.0, 0.5 * (1.0 + c.time_scale_min), c.time_scale_min])
            out[2:] = self.rng.choice(levels, n - 2)
            out = np.maximum(out, 1.0 - room / c.replan_period)
        return out

    def _score_attitude(self, out, nom: SampledTrajectory, tau: np.ndarray,
                        plan: "AttitudePlan", start: RolloutStart, scales: np.ndarray,
                        T: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """_score's terms against the time-scaled nominal, plus attitude error, the pair's
        angular momentum at the end and the delay: (costs, clearance, final attitude error)."""
        c = self.config
        costs, clr = self._score(out, nom, tau[0], plan.nominal_rotation[0, 1:], start)
        # tracking against each candidate's own (time-scaled) nominal instead of candidate 0's
        p_nom0 = _interp(nom.t, nom.position, tau[0])
        p_nom = _interp(nom.t, nom.position, tau.ravel()).reshape(tau.shape + (3,))
        dev = np.sum((out.robot_position - p_nom) ** 2, -1)
        costs = costs + c.w_track * (
            np.mean(dev, axis=1) - np.mean(np.sum((out.robot_position - p_nom0) ** 2, -1), axis=1))
        costs = costs + c.w_collision * (np.sqrt(dev.max(axis=1)) > c.max_deviation)
        sl = slice(c.cost_stride - 1, None, c.cost_stride)
        Rn = plan.nominal_rotation[:, 1:][:, sl]                       # (N, K, 3, 3)
        Rr = out.rotation[:, sl]
        e = _log_so3(np.swapaxes(Rn, -1, -2).reshape(-1, 3, 3) @ Rr.reshape(-1, 3, 3))
        e2 = np.sum(e.reshape(Rn.shape[:2] + (3,)) ** 2, -1)           # (N, K) rad^2
        L = out.omega[:, -1] @ out.inertia.T                            # body frame, N m s
        return (costs + c.w_attitude * np.mean(e2, axis=1) + c.w_momentum * np.sum(L * L, -1)
                + c.w_delay * (1.0 - scales) * T), clr, np.sqrt(e2[:, -1])

    def _executed_attitude(self, points: np.ndarray, now: float, T: float,
                           plan: "AttitudePlan", best: int, tau_h: float) -> SampledTrajectory:
        """The chosen candidate (position, its attitude reference) at ~10 Hz, then the rest
        of the nominal, shifted by the candidate's delay."""
        nom = self.nominal
        k = max(2, int(math.ceil(T * 10.0)) + 1)
        s = np.linspace(0.0, 1.0, k)
        p, v, a = (x[0] for x in _bezier_states(points[None], T, s))
        t = now + s * T
        u = s * (plan.rotation.shape[1] - 1)                            # rollout grid index
        idx = np.minimum(np.round(u).astype(int), plan.rotation.shape[1] - 1)
        p = p + plan.shift[best, idx]
        v = v + plan.shift_velocity[best, idx]
        a = a + plan.shift_accel[best, idx]
        q = rot.from_matrix(plan.rotation[best, idx])
        w = plan.omega[best, idx]
        al = plan.alpha[best, idx]
        shift = (now + T) - tau_h
        tail = nom.t > tau_h + 1e-6
        return _joined((t, p, v, a, q, w, al), nom, tail, shift)

    def _start(self, state: State) -> RolloutStart:
        mass = self.tracker.robot_mass.mass
        ff = self.tracker.pd.mass.mass
        b = self.bag
        if b is None:
            return RolloutStart(state.position, state.velocity, mass, ff)
        return RolloutStart(state.position, state.velocity, mass, ff, np.asarray(b.position, float),
                            np.asarray(b.velocity, float), float(b.mass),
                            np.asarray(b.size, float), self.rest_offset, self.bag_rotation,
                            np.asarray(state.orientation, float), np.asarray(state.omega, float),
                            self.tracker.robot_mass.inertia, self.tracker.pd.mass.inertia)

    def _score(self, out, nom: SampledTrajectory, times: np.ndarray, rotation: np.ndarray,
               start: RolloutStart) -> tuple[np.ndarray, np.ndarray]:
        c = self.config
        p_nom = np.stack([np.interp(times, nom.t, nom.position[:, k]) for k in range(3)], -1)
        track = np.mean(np.sum((out.robot_position - p_nom) ** 2, -1), axis=1)
        effort = np.mean(np.sum(out.force ** 2, -1), axis=1)
        sl = slice(c.cost_stride - 1, None, c.cost_stride)
        R = rotation[sl]                                             # (K, 3, 3)
        reach = c.clearance_margin + 0.3
        # robot: its centre, less half its envelope (the faces; corners are left out, as the
        # planner's own radius already keeps them off the walls along the nominal)
        clr = self.keep_in.clearance(out.robot_position[:, sl], reach).min(axis=1) \
            - c.robot_half_size
        relvel = np.zeros_like(track)
        if out.bag_position is not None:
            body_c = (_CUBE * (start.bag_size / 2)) @ start.bag_rotation.T      # (8, 3) body
            turn = getattr(out, "bag_turn", None)
            if turn is None:
                bag_c = np.einsum("kij,pj->kpi", R, body_c)[None]            # (1, K, 8, 3)
            else:   # the bag turned (rotation vector, start body frame) since the start
                bag_c = np.einsum("ij,nkpj->nkpi", rotation[0] if start.robot_orientation is None
                                  else rot.to_matrix(start.robot_orientation),
                                  rotate_by(turn[:, sl, None, :], body_c[None, None]))
            corners = out.bag_position[:, sl, None, :] + bag_c            # (N, K, 8, 3)
            clr = np.minimum(clr, self.keep_in.clearance(corners, reach).min(axis=(1, 2)))
            relvel = np.mean(np.sum((out.bag_velocity - out.robot_velocity) ** 2, -1), axis=1)
        intrusion = np.maximum(c.clearance_margin - clr, 0.0)
        costs = (c.w_track * track + c.w_effort * effort + c.w_relvel * relvel
                 + c.w_clearance * intrusion ** 2 + c.w_collision * (clr < 0))
        return costs, clr

    def _executed(self, points: np.ndarray, now: float, T: float) -> SampledTrajectory:
        """The chosen candidate sampled at ~10 Hz, then the nominal after its end; attitude,
        angular rate and acceleration from the nominal."""
        nom = self.nominal
        n = max(2, int(math.ceil(T * 10.0)) + 1)
        s = np.linspace(0.0, 1.0, n)
        p, v, a = (x[0] for x in _bezier_states(points[None], T, s))
        t = now + s * T
        tail = nom.t > t[-1] + 1e-6
        refs = [nom.sample(ti) for ti in t]
        q = np.array([r.orientation for r in refs])
        w = np.array([r.omega for r in refs])
        al = np.array([r.alpha for r in refs])
        return _joined((t, p, v, a, q, w, al), nom, tail)


def _joined(head: tuple, nom: SampledTrajectory, tail: np.ndarray,
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


@dataclass
class AttitudePlan:
    """Per-candidate attitude references on the rollout grid (m+1 points): body -> world
    rotations, world-frame rate and acceleration; the time-scaled nominal's rotations; each
    candidate's recovery time (inf: nominal attitude); the recovery's start offset and rate
    and the pair's inertia, from which `peak_torque` is derived on demand (not per decision)."""

    rotation: np.ndarray          # (N, m+1, 3, 3)
    omega: np.ndarray             # (N, m+1, 3) rad/s, world
    alpha: np.ndarray             # (N, m+1, 3) rad/s^2, world
    nominal_rotation: np.ndarray  # (N, m+1, 3, 3)
    recovery_time: np.ndarray     # (N,) s
    shift: np.ndarray             # (N, m+1, 3) m, position reference shift (world)
    shift_velocity: np.ndarray    # (N, m+1, 3)
    shift_accel: np.ndarray       # (N, m+1, 3)
    offset: np.ndarray            # (3,) rad, the present attitude offset to the nominal
    offset_rate: np.ndarray       # (3,) rad/s, the recovery's starting rate
    inertia: np.ndarray           # (3, 3) kg m^2, the pair about its centre of mass

    @property
    def peak_torque(self) -> np.ndarray:
        """(N, 3) N m, body axes: each recovery's peak feed-forward torque I delta'' (0 for the
        candidates that keep the nominal attitude)."""
        peak = np.zeros((len(self.recovery_time), 3))
        grid = np.linspace(0.0, 1.0, 21)
        for i in np.flatnonzero(np.isfinite(self.recovery_time)):
            Tc = self.recovery_time[i:i + 1]
            _, _, ap = recovery_profile(self.offset, self.offset_rate, Tc, grid * Tc[0])
            peak[i] = np.abs(ap[0] @ np.asarray(self.inertia).T).max(axis=0)
        return peak


RECOVERY_TIMES = np.geomspace(0.5, 40.0, 24)   # s, the recovery durations tried


def recovery_profile(e0: np.ndarray, r0: np.ndarray, Tc: np.ndarray, t: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic offset delta(t) (and its first two derivatives) from (e0, r0, 0) at t = 0 to
    rest at zero at t = Tc, zero after; e0, r0 (3,), Tc (N,), t (M,) -> (N, M, 3) each."""
    Tc = np.asarray(Tc, float)[:, None]
    u = np.clip(t[None, :] / Tc, 0.0, 1.0)[..., None]          # (N, M, 1)
    inside = (t[None, :] < Tc)[..., None]
    T = Tc[..., None]
    h0 = 1 - 10 * u ** 3 + 15 * u ** 4 - 6 * u ** 5
    h1 = u - 6 * u ** 3 + 8 * u ** 4 - 3 * u ** 5
    d0 = -30 * u ** 2 + 60 * u ** 3 - 30 * u ** 4
    d1 = 1 - 18 * u ** 2 + 32 * u ** 3 - 15 * u ** 4
    dd0 = -60 * u + 180 * u ** 2 - 120 * u ** 3
    dd1 = -36 * u + 96 * u ** 2 - 60 * u ** 3
    x = e0 * h0 + r0 * T * h1
    v = (e0 * d0 + r0 * T * d1) / T * inside
    a = (e0 * dd0 + r0 * T * dd1) / (T * T) * inside
    return x, v, a


def shortest_recovery(e0: np.ndarray, r0: np.ndarray, inertia: np.ndarray,
                      max_torque: np.ndarray, margin: float) -> float:
    """The shortest of RECOVERY_TIMES whose feed-forward torque I delta'' stays within
    margin x the torque limits on every body axis (the longest when none does)."""
    t = np.linspace(0.0, 1.0, 21)
    ok = []
    for Tc in RECOVERY_TIMES:
        _, _, a = recovery_profile(e0, r0, np.array([Tc]), t * Tc)
        tq = np.abs(a[0] @ np.asarray(inertia).T).max(axis=0)
        ok.append(bool(np.all(tq <= margin * max_torque + 1e-12)))
    return float(RECOVERY_TIMES[ok.index(True)] if any(ok) else RECOVERY_TIMES[-1])


def attitude_candidates(nom: SampledTrajectory, tau: np.ndarray, t: np.ndarray, state: State,
                        scales: np.ndarray, inertia: np.ndarray, max_torque: np.ndarray,
                        config: MpcConfig, rng: np.random.Generator, n: int,
                        centre: np.ndarray | None = None) -> AttitudePlan:
    """The candidates' attitude references (AttitudePlan) on the rollout grid: the time-scaled
    nominal's attitude for the first ones (candidate 0 is the nominal), and for the last
    `attitude_share` (the warm start, candidate 1, among them) a torque-feasible recovery
    from the present attitude offset and rate (recovery_profile, shortest_recovery). A
    recovery candidate's position reference is shifted by (R_nom - R_ref) c (c: robot ->
    pair's centre of mass, body; `centre`): the pair turns about its centre of mass, where the
    position loop does not fight the turn with an off-centre force (blended in from zero at
    the start, where the candidate leaves from the robot's present position)."""
    q_nom = _interp(nom.t, nom.orientation, tau.ravel())
    Rn = rot.to_matrix(q_nom / np.linalg.norm(q_nom, axis=-1, keepdims=True)).reshape(
        tau.shape + (3, 3))
    w_nom = _interp(nom.t, nom.omega, tau.ravel()).reshape(tau.shape + (3,)) * scales[:, None, None]
    a_nom = _interp(nom.t, nom.alpha, tau.ravel()).reshape(tau.shape + (3,)) * \
        (scales ** 2)[:, None, None]
    R_now = rot.to_matrix(np.asarray(state.orientation, float))
    R0 = Rn[0, 0]
    e0 = _log_so3((R0.T @ R_now)[None])[0]                     # R_now = R0 exp(e0)
    # the recovery leaves from the present attitude at the nominal's rate, not the present
    # rate: re-anchored every replan at the measured rate, it would let a spin run on
    r0 = np.zeros(3)
    k = int(round(config.attitude_share * n))
    first = max(2, n - k) if k > 0 else n
    Tc = np.full(n, np.inf)
    rotation, omega, alpha = Rn.copy(), w_nom.copy(), a_nom.copy()
    if first < n:
        T0 = shortest_recovery(e0, r0, inertia, max_torque, config.torque_margin)
        Tc[first:] = T0 * rng.uniform(1.0, 2.5, n - first)
        Tc[first] = T0
        Tc[1] = T0 * 1.25
        sel = np.r_[1, np.arange(first, n)]
        x, v, a = recovery_profile(e0, r0, Tc[sel], t)
        E = _exp_so3(x.reshape(-1, 3)).reshape(x.shape + (3,))
        rotation[sel] = Rn[sel] @ E
        omega[sel] = w_nom[sel] + np.einsum("nmij,nmj->nmi", rotation[sel], v)
        alpha[sel] = a_nom[sel] + np.einsum("nmij,nmj->nmi", rotation[sel], a)
    shift = np.zeros(tau.shape + (3,))
    if centre is not None and first < n:
        c = np.asarray(centre, float)
        shift = (Rn - rotation) @ c                                  # (N, m+1, 3)
        u = t / max(float(t[-1]), 1e-9)
        fade = (1 - 10 * u ** 3 + 15 * u ** 4 - 6 * u ** 5)[None, :, None]
        shift = shift - shift[:, :1] * fade
    dt = float(t[1] - t[0]) if len(t) > 1 else 1.0
    sv = np.gradient(shift, dt, axis=1)
    return AttitudePlan(rotation, omega, alpha, Rn, Tc, shift, sv, np.gradient(sv, dt, axis=1),
                        e0, r0, np.asarray(inertia, float))


def _interp(t: np.ndarray, values: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Per-axis linear interpolation of (T, k) samples at times `at` (...,) -> (..., k),
    clamped at the ends."""
    at = np.asarray(at, float)
    return np.stack([np.interp(at.ravel(), t, values[:, k]) for k in range(values.shape[1])],
                    -1).reshape(at.shape + (values.shape[1],))


def _append_hold(traj: SampledTrajectory, t_end: float) -> SampledTrajectory:
    """`traj` followed by its final pose held (at rest) until t_end."""
    final = traj.final()
    z = np.zeros(3)
    return SampledTrajectory(np.append(traj.t, t_end), np.vstack([traj.position, final.position]),
                             np.vstack([traj.velocity, z]), np.vstack([traj.accel, z]),
                             np.vstack([traj.orientation, final.orientation]),
                             np.vstack([traj.omega, z]), np.vstack([traj.alpha, z]))


def _bezier_states(points: np.ndarray, T: float, s: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities, accelerations (N, M, 3) of quintic Beziers (N, 6, 3) of duration
    T at normalised times s (M,)."""
    B0 = bezier.bernstein(5, s)
    B1 = bezier.bernstein(4, s) @ bezier.difference_matrix(5, 1)
    B2 = bezier.bernstein(3, s) @ bezier.difference_matrix(5, 2)
    return (np.einsum("mi,nik->nmk", B0, points), np.einsum("mi,nik->nmk", B1, points) / T,
            np.einsum("mi,nik->nmk", B2, points) / (T * T))


def _interp_quat(traj: SampledTrajectory, times: np.ndarray) -> np.ndarray:
    """Orientation of a trajectory at many times: componentwise linear interpolation of its
    (hemisphere-aligned) samples, renormalised (a fine stand-in for slerp at 10 Hz samples)."""
    q = np.stack([np.interp(times, traj.t, traj.orientation[:, k]) for k in range(4)], -1)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


_CFG = asdict(MpcConfig())
# the MPC's parameters beyond every controller's (name -> default; MpcConfig owns the cost and
# sampling defaults, this table the model's): its node declares them as ROS parameters,
# in-process flights read them too
PARAMETERS = {**{k: _CFG[k] for k in ("samples", "horizon", "replan_period", "rollout_dt",
                                      "sigma_position", "sigma_velocity", "w_track", "w_collision",
                                      "w_clearance", "clearance_margin", "w_effort", "w_relvel",
                                      "seed", "attitude", "attitude_share", "torque_margin",
                                      "time_scale_min", "max_delay", "w_attitude", "w_momentum",
                                      "w_delay", "max_deviation", "min_gain",
                                      "hold_about_centre")},
              "model": "reduced", "handle": "fem", "pybullet_bag": "constraint", "workers": 2,
              "settle_time": SETTLE_TIME}


def check_params(params: dict) -> MpcConfig:
    """The MPC's parameters (PARAMETERS' names, missing ones at their defaults) checked without
    building the law or its model (ValueError with one line); the MpcConfig they make."""
    params = {**PARAMETERS, **params}
    config = MpcConfig.from_params(params)
    if str(params["model"]) not in MODELS:
        raise ValueError(f"unknown model {params['model']!r}; known: {', '.join(MODELS)}")
    w = params["workers"]
    if isinstance(w, bool) or not isinstance(w, int) or w <= 0:
        raise ValueError(f"workers must be a positive integer, got {w!r}")
    check_settle_time(params["settle_time"])
    return config


def make_rollout_model(params: dict) -> RolloutModel:
    """The rollout model the parameters name (missing ones at PARAMETERS' defaults; ValueError
    with one line otherwise)."""
    params = {**PARAMETERS, **params}
    model = str(params["model"])
    if model == "reduced":
        from .reduced_model import ReducedModel, identified_handles
        handles = identified_handles()
        name = str(params["handle"])
        if name not in handles:
            raise ValueError(f"no identified handle {name!r} in config/reduced_models.yaml; "
                             f"known: {', '.join(handles) or 'none'}")
        return ReducedModel(handles[name], handles)
    if model == "pybullet":
        from .rollout_pybullet import PybulletModel
        return PybulletModel(int(params["workers"]), str(params["pybullet_bag"]))
    raise ValueError(f"unknown model {model!r}; known: {', '.join(MODELS)}")


def make_mpc_law(flight_mode: FlightMode, mass: MassProperties, params: dict) -> MpcLaw:
    """The MPC law of the parameters (PARAMETERS' names; ValueError with one line for a bad
    value). mpc_controller_node and in-process flights build their law here."""
    config = check_params(params)
    settle = check_settle_time({**PARAMETERS, **params}["settle_time"])
    return MpcLaw(flight_mode, mass, make_rollout_model(params), config, settle_time=settle)


# the registry entry (astrobee_control.registry; pyproject's astrobee.controllers group)
CONTROLLER = Controller("mpc", make_mpc_law, PARAMETERS, check_params,
                        "sampling MPC over a rollout model of robot + bag (reduced | pybullet)",
                        executable="mpc_controller_node")
