"""A cargo-transport leg flown in-process: the simulator library, the planner library and a
control law in one loop, with no router and no processes.

The loop mirrors the graph (sim_node in lockstep + planner_node + controller_node + mission):
the planner is called as /mob/planner/global calls it (the robot's pose at the start, the
scenario's goal, flight mode, face_forward and carry extent; sampled at planner_node's 10 Hz);
the law is built by the same registry entry as the controller node (astrobee_control.registry:
the law's defaults, then config/controllers.yaml's section) and sees the EKF state at 62.5 Hz,
the carried bag as controller_node builds it (BagObservation with the mass the robot is told),
one tick late as on the graph; its body-frame wrench (optionally through the CBF safety filter,
as safety_filter_node) is held for the physics steps up to the next tick (350 Hz); a
astrobee.task.TaskMonitor judges the leg. Same arguments and seed give the same result.

    res = Flight("node2_to_jem_bag", seed=0, controller="pd").run()
    res.success, res.cause, res.row()      # one flat row for a study table
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from astrobee import flight_modes
from astrobee import rotations as rot
from astrobee.overrides import parse_overrides
from astrobee.scenario import Scenario
from astrobee.task import Task, TaskMonitor, TaskSample

CONTROL_RATE = 62.5        # Hz: the sim's publish rate, one command per state
PLAN_SAMPLE_RATE = 10.0    # Hz: planner_node's default segment sampling
FAULT_WATCH = 0.5          # s a faulted flight is watched before it ends (as the mission)


@dataclass
class FlightResult:
    """How a flight went: verdict, figures, costs and what was flown (see row())."""

    success: bool
    cause: str
    metrics: dict[str, Any]
    compute_ms_median: float
    compute_ms_p99: float
    wall_time: float
    sim_time: float
    plan_duration: float
    planning_time: float
    ticks: int
    setup: dict[str, Any] = field(default_factory=dict)

    def row(self) -> dict[str, Any]:
        """One flat row: the setup, the verdict, the metrics and the costs."""
        return {**self.setup, "success": self.success, "cause": self.cause, **self.metrics,
                "plan_duration": self.plan_duration, "planning_time": self.planning_time,
                "sim_time": self.sim_time, "wall_time": self.wall_time,
                "real_time_factor": self.sim_time / self.wall_time if self.wall_time > 0 else math.nan,
                "compute_ms_median": self.compute_ms_median, "compute_ms_p99": self.compute_ms_p99,
                "ticks": self.ticks}


@dataclass
class RobotObs:
    """One robot at one tick: what the law saw and decided."""

    state: Any                    # astrobee_control.pd.State, the EKF's (law input)
    truth: tuple                  # (position, orientation, velocity, omega world)
    reference: Any                # astrobee_control.pd.Reference of this tick
    nominal: np.ndarray           # the law's (filtered) body wrench for the next interval
    law_state: int                # MotionState value


@dataclass
class FlightObs:
    """What one tick shows: time, every robot, the bag (None without one)."""

    t: float
    robots: dict[str, RobotObs]
    bag: Any                      # astrobee_sim BagState or None


def make_controller(controller: str | Any, flight_mode, params: dict | None = None):
    """The law a registered controller name stands for (astrobee_control.registry), built as
    its node builds it (the law's defaults, config/controllers.yaml's section, then `params`);
    a ControlLaw object, or a callable (flight_mode, mass, params) -> law, is used as given."""
    from astrobee_control import mass as mp
    from astrobee_control import registry
    if isinstance(controller, str):
        try:
            law = registry.get(controller)
        except registry.UnknownController:
            raise ValueError(f"controller must be {registry.choices_text()} or a ControlLaw, "
                             f"got {controller!r}") from None
        return law.make(flight_mode, mp.robot(), params)
    if callable(controller) and not hasattr(controller, "update"):
        return controller(flight_mode, mp.robot(), dict(params or {}))
    return controller


class Flight:
    """One leg in-process (see the module docstring): one robot, or two holding one bag (one law
    each, the formation planner's references; each law told its share of the bag's mass, as
    the launch tells each controller node)."""

    def __init__(self, scenario: str | Scenario = "node2_to_jem_bag", seed: int = 0,
                 controller: str | Any = "pd", safety: bool = False, *,
                 bag_model: str | None = None, bag_variant: str | None = None,
                 bag_resolution: int | None = None, bag_mass: float | None = None,
                 fem_solver: str | None = None, flight_mode: str | None = None,
                 realism: Any = None, controller_params: dict | None = None,
                 state_source: str = "ekf", task: dict | None = None,
                 physics_rate: float | None = None, plan: bool = True,
                 backend: Any = None) -> None:
        """scenario: a name of config/scenarios (with the overrides, as the launch applies
        them) or a Scenario as is. controller: a registered law's name ('pd', 'mpc', ...) | a ControlLaw | a factory.
        safety: the CBF filter between the law and the sim. realism: a preset name of
        config/realism.yaml, a mapping of knobs or an astrobee.realism.Realism (the scenario's
        otherwise). state_source: 'ekf' (the law sees the estimate) | 'truth'.
        task: keywords of Task.from_scenario (settle_budget, time_limit, end_on_contact,
        weights, goals...).
        plan: False flies no segment (the law holds the start pose; environments in wrench
        mode use the reference only for the observation).
        backend: the simulator: None, the pybullet Simulation (astrobee_sim); a SimBackend
        object (reset to this flight's scenario and seed), or a factory (scenario, seed) -> one.
        A backend without ekf_state() gives the law the truth; without told_bag_mass(), the
        scenario's realism bag_mass_told is applied to the bag's mass."""
        overrides = parse_overrides({"bag_model": bag_model, "bag_variant": bag_variant,
                                     "bag_resolution": bag_resolution, "bag_mass": bag_mass,
                                     "fem_solver": fem_solver, "flight_mode": flight_mode,
                                     "realism": realism})
        if isinstance(scenario, Scenario):
            self.scenario = overrides.apply(scenario)
        elif isinstance(scenario, str):
            self.scenario = Scenario.load(scenario, overrides)
        else:
            raise ValueError(f"scenario must be a name or a Scenario, got {type(scenario).__name__}")
        if len(self.scenario.robots) not in (1, 2):
            raise ValueError(f"scenario {self.scenario.name!r} has {len(self.scenario.robots)} robots: "
                             "in-process flights fly one robot, or two holding one bag")
        if self.scenario.goal_position is None:
            raise ValueError(f"scenario {self.scenario.name!r} has no goal")
        if state_source not in ("ekf", "truth"):
            raise ValueError(f"state_source must be ekf or truth, got {state_source!r}")
        self.seed = int(seed)
        self.controller = controller
        self.controller_params = dict(controller_params or {})
        self.safety = bool(safety)
        self.realism = realism
        self.state_source = state_source
        self.task_kw = dict(task or {})
        self.physics_rate = physics_rate
        self.backend = backend
        self.plan_enabled = bool(plan)
        self.mode = flight_modes.get(self.scenario.flight_mode)
        self.sim: Any = None
        self.names = [r.name for r in self.scenario.robots]
        self.monitor: TaskMonitor | None = None
        self.traj: Any = None               # the first robot's reference
        self.trajs: dict[str, Any] = {}     # every robot's
        self._closed = False

    # ---- setup ----------------------------------------------------------------------------
    def _make_sim(self, seed: int) -> None:
        if self.sim is not None:
            self.sim.reset(self.scenario, seed)
        elif self.backend is None:
            from astrobee_sim.simulation import Simulation
            self.sim = Simulation(self.scenario, seed=seed, physics_rate=self.physics_rate)
        elif callable(self.backend) and not hasattr(self.backend, "step"):
            self.sim = self.backend(self.scenario, seed)
        else:
            self.sim = self.backend
            self.sim.reset(self.scenario, seed)
        self.dt = self.sim.dt

    def _law(self):
        law = make_controller(self.controller, self.mode, self.controller_params)
        law.set_flight_mode(self.mode)
        return law

    def reset(self, seed: int | None = None, scenario: Scenario | None = None) -> FlightObs:
        """Rebuild the world (seed None: the flight's), plan the leg and take tick 0."""
        from astrobee_control import mass as mp
        if seed is not None:
            self.seed = int(seed)
        if scenario is not None:
            if [r.name for r in scenario.robots] != self.names or scenario.goal_position is None:
                raise ValueError(f"a reset scenario needs the robots {self.names} and a goal")
            self.scenario = scenario
            self.mode = flight_modes.get(scenario.flight_mode)
        self._make_sim(self.seed)
        sim = self.sim
        self.tick = 0
        self.plan_duration = math.nan
        self.planning_time = math.nan
        self.compute_s: list[float] = []
        self._close_laws()
        self.laws = {n: self._law() for n in self.names}
        self.filters: dict[str, Any] = {}        # robot -> safety.LawFilter (as the nodes')
        if self.safety:
            from astrobee_control.safety import LawFilter
            self.filters = {n: LawFilter(self.mode, mp.robot()) for n in self.names}
        self._bag_obs: dict[str, Any] = {n: None for n in self.names}
        self._told_mass = self._bag_mass()
        self._fault_t: float | None = None
        self._plan_error = ""
        self._steps: dict[str, Any] = {}
        self._wrench: dict[str, np.ndarray] = {}
        self._applied: dict[str, np.ndarray] = {}
        # tick 0: the law takes the start pose (holds it), then the segment comes (as the
        # mission hands it over once the controller holds)
        self._read()
        for n in self.names:
            self._update_law(n, hold_only=True)
        self.traj, self.trajs = None, {}
        if self.plan_enabled:
            self._plan()
            for n, traj in self.trajs.items():
                self.laws[n].follow(traj, sim.time)
        # the budget: the plan's end + the task's settle_budget (astrobee.task's default)
        self.task = Task.from_scenario(self.scenario, plan_duration=None if math.isnan(
            self.plan_duration) else self.plan_duration, **self.task_kw)
        self.monitor = self.task.monitor()
        if self._plan_error:
            self.monitor.fail(self._plan_error)
        self._pending = {n: self._command(n) for n in self.names}
        sample = self._sample()
        self.monitor.update(sample)
        self.last_sample = sample
        return self._obs()

    def _bag_mass(self) -> float | None:
        """The bag mass each law is told: the simulator's told mass (realism bag_mass_told),
        shared evenly when every handle is held by its own robot (as the launch gives each
        controller node its share)."""
        sc = self.scenario
        if sc.bag is None:
            return None
        told_fn = getattr(self.sim, "told_bag_mass", None)
        told = float(told_fn()) if told_fn is not None else sc.realism.told_mass(sc.bag.mass)
        mass = told if told > 0 else float(sc.bag.mass)
        n = len(self.names)
        return mass / n if n > 1 and sc.bag.handles == n else mass

    def _plan(self) -> None:
        """The leg's references from the planner library, as planner_node makes them: one robot
        as /mob/planner/global (its pose, the scenario's goal, face_forward, carry extent), two
        as /mob/planner/formation (both poses, the first robot's goal, the bag's pose and size)."""
        from astrobee_control.reference import SampledTrajectory
        from astrobee_planning import multi_robot, planner
        sc = self.scenario
        self._plan_error = ""
        goal = (np.asarray(sc.goal_position, float),
                rot.normalize(np.asarray(sc.goal_orientation, float)))
        starts = [(self._truth[n][0], rot.normalize(self._truth[n][1])) for n in self.names]
        t0 = time.perf_counter()
        try:
            if len(self.names) == 1:
                plan = planner.plan_global(starts[0][0], starts[0][1], goal[0], goal[1],
                                           self.mode.name, bool(sc.face_forward),
                                           float(sc.carry_extent) if sc.carrying_bag else 0.0)
                trajs = [plan.trajectory]
                duration = plan.trajectory.duration
            else:
                bag = self._bag
                bag_pose = None if bag is None else (np.asarray(bag.position, float),
                                                     rot.normalize(bag.orientation))
                plan = multi_robot.plan_formation(starts, goal, bag_pose,
                                                  None if sc.bag is None else list(sc.bag.size),
                                                  self.mode.name)
                trajs = plan.robots
                duration = plan.formation.centre.trajectory.duration
        except planner.PlanError as exc:
            self.planning_time = time.perf_counter() - t0
            self._plan_error = f"planning failed (code {exc.code}): {exc}"
            return
        self.planning_time = time.perf_counter() - t0
        self.plan_duration = float(duration)
        for n, traj in zip(self.names, trajs):
            st = traj.sample_rate(PLAN_SAMPLE_RATE)
            self.trajs[n] = SampledTrajectory(st.t, st.pos, st.vel, st.acc, st.quat, st.omega,
                                              st.alpha)
        self.traj = self.trajs[self.names[0]]

    # ---- one tick -------------------------------------------------------------------------
    def _read(self) -> None:
        """This tick's truth and estimated states of every robot, and the bag."""
        from astrobee_control.pd import State
        sim = self.sim
        self._truth = {n: sim.robot_state(n) for n in self.names}
        ekf = getattr(sim, "ekf_state", None) if self.state_source == "ekf" else None
        self._state = {}
        for n in self.names:
            # (position, orientation, velocity, omega) world frame -> State with BODY omega,
            # as sim_node's /gnc/ekf and controller_node's ekf_state() make it
            p, q, v, w = ekf(n) if ekf is not None else self._truth[n]
            qn = rot.normalize(np.asarray(q, float))
            self._state[n] = State(np.array(p, float), np.array(v, float), qn,
                                   rot.rotate_inverse(qn, np.asarray(w, float)))
        self._bag = sim.bag_state()

    def _update_law(self, n: str, hold_only: bool = False) -> None:
        law = self.laws[n]
        state = self._state[n]
        t = self.sim.time
        dt = 1.0 / CONTROL_RATE
        c0 = time.perf_counter()
        step = law.update(state, t, dt)
        wrench = np.concatenate([step.output.force, step.output.torque])
        filt = self.filters.get(n)
        if filt is not None:
            res = filt.apply(wrench[:3], wrench[3:], state)
            wrench = np.concatenate([res.force, res.torque])
        if not hold_only:
            self.compute_s.append(time.perf_counter() - c0)
        self._steps[n] = step
        self._wrench[n] = wrench
        # the bag state of this tick reaches the law after its command (as on the graph)
        self._observe_bag(n, state)

    def _observe_bag(self, n: str, state: Any) -> None:
        from astrobee_control.law import BagObservation
        bag, sc = self._bag, self.scenario
        law = self.laws[n]
        attached = bag is not None and bool(np.any(np.asarray(bag.attached, bool)))
        if not attached or self._told_mass is None:
            if self._bag_obs[n] is not None:
                law.observe_bag(None, state)
                self._bag_obs[n] = None
                if n in self.filters:
                    self.filters[n].release()
            return
        obs = BagObservation(np.asarray(bag.position, float), rot.normalize(bag.orientation),
                             np.asarray(bag.velocity, float), np.asarray(bag.omega, float), True,
                             self._told_mass, np.asarray(sc.bag.size, float), sc.bag.model)
        law.observe_bag(obs, state)
        self._bag_obs[n] = obs
        if n in self.filters:        # the held bag's mass and extent, rebuilt on a 1 cm move
            self.filters[n].observe_bag(obs, state)

    def _command(self, n: str) -> np.ndarray:
        return self._wrench[n]

    def step(self, action: dict[str, np.ndarray] | np.ndarray | None = None,
             mode: str = "add") -> tuple[FlightObs, TaskSample]:
        """One control tick: the pending wrench (the law's, with `action` added, or replaced
        with mode='replace'; body frame [fx fy fz tx ty tz], per robot or one array for the
        only robot) is held for the physics steps to the next tick; then the new state is read,
        the law decides the next wrench and the monitor takes the tick's sample."""
        if self.monitor is None:
            raise RuntimeError("reset() the flight before step()")
        sim = self.sim
        for n in self.names:
            w = self._pending[n]
            if action is not None:
                a = action.get(n) if isinstance(action, dict) else action
                if a is not None:
                    a = np.asarray(a, float).reshape(6)
                    w = a if mode == "replace" else w + a
            self._applied[n] = w
            sim.command(w, n)
        self.tick += 1
        target = int(round(self.tick / CONTROL_RATE / sim.dt))
        sim.step(max(1, target - sim.steps))
        self._read()
        for n in self.names:
            self._update_law(n)
        self._pending = {n: self._command(n) for n in self.names}
        sample = self._sample()
        self.monitor.update(sample)
        self.last_sample = sample
        return self._obs(), sample

    def _sample(self) -> TaskSample:
        sim = self.sim
        positions = [self._truth[n][0] for n in self.names]
        rc, bc = sim.clearance(positions)
        contacts = sim.contacts()
        # sim_node's /sim/fault wording (the mission's summary quotes it)
        faults = {n: (f"sim/propulsion_watchdog: no command for {sim.watchdog_timeout:g} s: "
                      "propulsion stopped (code 1)",) for n in self.names if sim.faulted(n)}
        bag = self._bag
        rel = math.nan
        if bag is not None:
            rel = float(np.linalg.norm(np.asarray(bag.velocity) - self._truth[self.names[0]][2]))
        applied = self._applied or self._pending
        lim = np.concatenate([self.mode.max_force, self.mode.max_torque])
        lim = np.where(lim > 0, lim, 1.0)
        effort = float(np.mean([np.mean((applied[n] / lim) ** 2) for n in self.names]))
        return TaskSample(
            t=sim.time,
            poses={n: (self._truth[n][0], self._truth[n][1]) for n in self.names},
            velocities={n: (self._truth[n][2], self._truth[n][3]) for n in self.names},
            reference={n: self._steps[n].reference.position for n in self.names
                       if self._steps[n].control_mode != 0},
            reference_attitude={n: self._steps[n].reference.orientation for n in self.names
                                if self._steps[n].control_mode != 0},
            contacts=len(contacts),
            contact_bodies=tuple(sorted({f"{c.body_a}-{c.body_b}" for c in contacts})),
            touching=tuple(sorted({c.body_a for c in contacts})),
            robot_clearance=float(rc), bag_clearance=float(bc), faults=faults,
            bag_robot_speed=rel, effort=effort)

    def _obs(self) -> FlightObs:
        return FlightObs(self.sim.time, {n: RobotObs(self._state[n], self._truth[n],
                                                     self._steps[n].reference, self._pending[n],
                                                     int(self.laws[n].state))
                                         for n in self.names}, self._bag)

    # ---- the whole leg ----------------------------------------------------------------------
    def finished(self) -> bool:
        """The leg is over as the mission sees it: the Task's goal reached (every robot at rest
        at its goal; the laws keep holding, their own STOPPED ends nothing), a fault watched
        for FAULT_WATCH s, a failure before flight, or the time budget out."""
        m = self.monitor
        if m.failure or (self.traj is None and self.plan_enabled):
            return True
        if m.faults:
            if self._fault_t is None:
                self._fault_t = self.sim.time
            if self.sim.time - self._fault_t >= FAULT_WATCH:
                return True
        if self.traj is not None and m.goal_reached:
            return True
        return m.truncated

    def run(self, max_time: float | None = None, reset: bool = True) -> FlightResult:
        """Fly the whole leg (reset first unless told not to); `max_time` (sim s) replaces the
        task's time limit."""
        wall0 = time.perf_counter()
        if reset or self.monitor is None:
            self.reset()
        if max_time is not None:
            self.task.time_limit = float(max_time)
        t0 = self.sim.time
        while not self.finished():
            self.step()
        return self.result(time.perf_counter() - wall0, self.sim.time - t0)

    def result(self, wall_time: float, sim_time: float) -> FlightResult:
        ok, cause = self.monitor.verdict()
        comp = np.asarray(self.compute_s) * 1e3 if self.compute_s else np.array([math.nan])
        return FlightResult(ok, cause, self.monitor.metrics(), float(np.median(comp)),
                            float(np.percentile(comp, 99)), wall_time, sim_time,
                            self.plan_duration, self.planning_time, self.tick, self.setup())

    def setup(self) -> dict[str, Any]:
        """What was flown, flat: scenario, bag, flight mode, controller, safety, realism, seed."""
        sc = self.scenario
        ctl = self.controller if isinstance(self.controller, str) else \
            getattr(self.controller, "name", type(self.controller).__name__)
        realism = self.realism if isinstance(self.realism, str) else \
            (",".join(f"{k}={v}" for k, v in sc.realism.changed().items()) or "off")
        return {"scenario": sc.name, "bag_model": sc.bag.model if sc.bag else "none",
                "bag_variant": sc.bag.variant if sc.bag else "",
                "bag_mass": sc.bag.mass if sc.bag else 0.0,
                "bag_resolution": sc.bag.resolution if sc.bag else 0,
                "fem_solver": sc.bag.solver if sc.bag and sc.bag.model == "fem" else "",
                "robots": len(self.names), "flight_mode": self.mode.name, "controller": ctl, "safety": self.safety,
                "realism": realism, "state_source": self.state_source, "seed": self.seed}

    def _close_laws(self) -> None:
        """Free what a law holds beyond memory (the MPC's pybullet rollout workers)."""
        for law in getattr(self, "laws", {}).values():
            close = getattr(getattr(law, "model", None), "close", None)
            if callable(close):
                close()
        self.laws = {}

    def close(self) -> None:
        self._close_laws()
        if self.sim is not None:
            self.sim.close()
            self.sim = None

    def __enter__(self) -> "Flight":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
