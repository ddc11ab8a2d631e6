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
from .law import BagObservation
from .mass import MassProperties
from .pd import State
from .reduced_model import CandidateReferences, Gains, RolloutModel, RolloutStart, rotate_by
from .reference import SampledTrajectory
from .tracking import CONTROLLING, Step, Tracker

MODELS = ("reduced", "pybullet")
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
        self.samples, self.cost_stride = int(self.samples), int(self.cost_stride)
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


class MpcLaw:
    """Sampling MPC over a rollout model; a ControlLaw (law.py)."""

    name = "mpc"

    def __init__(self, flight_mode: FlightMode, mass: MassProperties, model: RolloutModel,
                 config: MpcConfig | None = None, keep_in: np.ndarray | None = None,
                 settle_time: float = 5.0) -> None:
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
                and now >= self._next_replan and now < self.nominal.end_time):
            self._next_replan = now + self.config.replan_period
            decision = self.decide(state, now)
            if decision is not None:
                self.tracker.traj = decision.executed
                self.last = decision
        step = self.tracker.update(state, now, dt)
        if decision is not None:
            step.candidates, step.chosen = decision.candidates, decision.chosen
        return step

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
        return SampledTrajectory(np.concatenate([t, nom.t[tail]]),
                                 np.concatenate([p, nom.position[tail]]),
                                 np.concatenate([v, nom.velocity[tail]]),
                                 np.concatenate([a, nom.accel[tail]]),
                                 np.concatenate([q, nom.orientation[tail]]),
                                 np.concatenate([w, nom.omega[tail]]),
                                 np.concatenate([al, nom.alpha[tail]]))


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
# the MPC's parameters beyond every controller's (name -> default): mpc_controller_node declares
# them as ROS parameters, in-process flights (astrobee_lab) read them too
PARAMETERS = {**{k: _CFG[k] for k in ("samples", "horizon", "replan_period", "rollout_dt",
                                      "sigma_position", "sigma_velocity", "w_track", "w_collision",
                                      "w_clearance", "clearance_margin", "w_effort", "w_relvel",
                                      "seed")},
              "model": "reduced", "handle": "fem", "pybullet_bag": "constraint", "workers": 2,
              "settle_time": 5.0}


def make_rollout_model(params: dict) -> RolloutModel:
    """The rollout model the parameters name (ValueError with one line otherwise)."""
    model = str(params.get("model", "reduced"))
    if model == "reduced":
        from .reduced_model import ReducedModel, identified_handles
        handles = identified_handles()
        name = str(params.get("handle", "fem"))
        if name not in handles:
            raise ValueError(f"no identified handle {name!r} in config/reduced_models.yaml; "
                             f"known: {', '.join(handles) or 'none'}")
        return ReducedModel(handles[name], handles)
    if model == "pybullet":
        from .rollout_pybullet import PybulletModel
        return PybulletModel(int(params.get("workers", 2)), str(params.get("pybullet_bag", "constraint")))
    raise ValueError(f"unknown model {model!r}; known: {', '.join(MODELS)}")


def make_mpc_law(flight_mode: FlightMode, mass: MassProperties, params: dict) -> MpcLaw:
    """The MPC law of the parameters (PARAMETERS' names; ValueError with one line for a bad
    value). mpc_controller_node and in-process flights build their law here."""
    config = MpcConfig.from_params(params)
    settle = float(params.get("settle_time", 5.0))
    if not settle > 0:
        raise ValueError(f"settle_time must be > 0 s, got {settle:g}")
    return MpcLaw(flight_mode, mass, make_rollout_model(params), config, settle_time=settle)
