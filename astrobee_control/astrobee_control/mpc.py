"""The sampling MPC ControlLaw (the paper's algorithm, with a closed-form rollout model).

Every `replan_period` seconds while a segment is being followed:
1. take the nominal reference at the horizon's end t_h = min(now + horizon, segment end) and
   sample N targets around it (position and velocity perturbed; candidate 0 is the nominal
   target itself, candidate 1 the previous best perturbation: the warm start; half the rest
   are drawn around zero, half around the warm start). Perturbations shrink to zero as t_h
   reaches the segment's end, so the goal is never moved;
2. turn each target into a candidate reference from the current state with the batched local
   planner's quintic (astrobee.bezier.control_points: one per candidate);
3. roll every candidate out with the PD law on a rollout model (reduced_model.RolloutModel:
   model A closed-form, or the pybullet model B) for the whole horizon, all N at once;
4. score each (tracking error to the nominal, clearance of robot AND bag corners to the keep-in
   union with a collision penalty, effort, bag-robot relative speed) and execute the best: the
   law's tracker (tracking.PdLaw, the PD law's state machine) is handed the chosen candidate
   followed by the rest of the nominal, so CONTROLLING/STOPPING/STOPPED, stop, rehold and
   segment_result behave exactly as with the PD law.

Attitude follows the nominal segment (the candidates perturb translation only), so all
candidates share one rotation per rollout step.

Attitude-aware mode (`attitude: true`): mpc_attitude.py.
"""
from __future__ import annotations

import math
from dataclasses import asdict

import numpy as np

from astrobee import rotations as rot
from astrobee.flight_modes import FlightMode
from astrobee.bezier import control_points

from .clearance import CUBE, KeepIn
from .law import BagObservation, Step
from .handle_models import identified_handles, rotate_by
from .mass import MassProperties
from .mpc_attitude import AttitudeMode
from .mpc_config import MODELS, Decision, MpcConfig
from .mpc_paths import bezier_states, interp_quat, joined
from .pd import State
from .reduced_model import CandidateReferences, Gains, RolloutModel, RolloutStart
from .reference import SampledTrajectory
from .registry import Controller
from .tracking import CONTROLLING, SETTLE_TIME, PdLaw, check_settle_time


class MpcLaw(AttitudeMode):
    """Sampling MPC over a rollout model; a ControlLaw (law.py)."""

    name = "mpc"

    def __init__(self, flight_mode: FlightMode, mass: MassProperties, model: RolloutModel,
                 config: MpcConfig | None = None, keep_in: np.ndarray | None = None,
                 settle_time: float = SETTLE_TIME) -> None:
        from astrobee import config as cfg
        self.config = (config or MpcConfig()).validate()
        self.model = model
        self.tracker = PdLaw(flight_mode, mass, settle_time=settle_time)
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

    # ---- ControlLaw plumbing: the PD law's state machine -------------------------------
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
        """One control tick: replan when due, then the PD law's step on the chosen plan."""
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
        ref_p, ref_v, ref_a = bezier_states(pts, T, s)
        times = now + np.arange(m + 1) * dt_r
        quats = interp_quat(nom, times)
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
            body_c = (CUBE * (start.bag_size / 2)) @ start.bag_rotation.T      # (8, 3) body
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
        p, v, a = (x[0] for x in bezier_states(points[None], T, s))
        t = now + s * T
        tail = nom.t > t[-1] + 1e-6
        refs = [nom.sample(ti) for ti in t]
        q = np.array([r.orientation for r in refs])
        w = np.array([r.omega for r in refs])
        al = np.array([r.alpha for r in refs])
        return joined((t, p, v, a, q, w, al), nom, tail)


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
        from .reduced_model import ReducedModel
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
