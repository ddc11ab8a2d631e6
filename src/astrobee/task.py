"""What success, failure and reward mean for one cargo-transport leg (transport-free).

A `Task` holds the goal of every robot, the flight mode's goal tolerances and a time limit; a
`TaskMonitor` is fed one `TaskSample` per control tick (live from an in-process flight or an
environment, or read back from a recorded bag) and keeps the leg's figures of merit. Its
`verdict()` is the one rule of success, used by the mission, Flight, the studies and recorded
bags alike: a leg succeeds when every robot is within the position and attitude tolerance of
its goal AND at rest (|v| < 1 cm/s, |w| < 0.02 rad/s, held for 2 s; judged on truth) before the
time budget (the plan's end + a settle budget, 30 s by default) runs out, with no contact with
the station and no fault. The leg ends there: at rest, or when the budget is out (a controller
keeps holding until told otherwise; its own "reached" test decides nothing). The cause names what
failed and on which robot; metrics() reports the time to rest and the largest attitude
excursion from the reference. `reward()` is the same judgement made
dense for reinforcement learning (progress toward the goal, tracking, contact, low clearance,
effort; a terminal bonus or penalty).

Multi-robot: the scenario's goal is the first robot's; every other robot keeps its start pose
relative to the first (the formation moves rigidly), unless goals are given explicitly.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Iterable

import numpy as np

from . import flight_modes
from . import rotations as rot

REST_SPEED = 0.01      # m/s: "at rest"
REST_OMEGA = 0.02      # rad/s
REST_HOLD = 2.0        # s the rest must be held (in tolerance) for the goal to count as reached
SETTLE_BUDGET = 30.0   # s after the plan's end the leg may take to come to rest
NO_PLAN_LIMIT = 300.0  # s: time limit of a task with no plan duration given


def _norm(v: Any) -> float:
    """|v|, as np.linalg.norm computes it for a 3-vector (the square root of the left-to-right
    sum of squares) but without its dispatch: the monitor takes four a tick."""
    a = np.asarray(v, float)
    if a.shape == (3,):
        x, y, z = a.tolist()
        return math.sqrt(x * x + y * y + z * z)
    return float(np.linalg.norm(a))


def robot_label(name: str) -> str:
    """A robot in a column name, and the simulator's name of it in contacts: its namespace,
    or 'robot' for the default one."""
    return name or "robot"


def robot_named(name: str) -> str:
    """How causes name a robot (as the mission's summary does): "robot bumble", "the default
    robot"."""
    return f"robot {name}" if name else "the default robot"


@dataclass(frozen=True)
class Goal:
    """One robot's goal pose (world frame, quaternion [x, y, z, w])."""

    position: np.ndarray
    orientation: np.ndarray


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the dense reward (per tick unless said otherwise)."""

    progress: float = 1.0          # per m of distance to the goal gained (summed over robots)
    tracking: float = 1.0          # per m s of distance to the reference
    contact: float = 1.0           # per tick in contact with the station
    clearance: float = 1.0         # per s spent at zero clearance (linear up to the margin)
    clearance_margin: float = 0.10  # m: clearance below this is penalised
    effort: float = 0.05           # per s at full thrust on every axis
    success: float = 10.0          # once, when the goal is reached at rest
    failure: float = 10.0          # once, on a contact/fault that ends the episode or a timeout


@dataclass
class TaskSample:
    """What one control tick tells the monitor (world frame, SI units)."""

    t: float                                            # sim s
    poses: dict[str, tuple[np.ndarray, np.ndarray]]     # robot -> (position, quaternion)
    velocities: dict[str, tuple[np.ndarray, np.ndarray]] | None = None  # robot -> (v, omega)
    reference: dict[str, np.ndarray] | None = None      # robot -> reference position
    reference_attitude: dict[str, np.ndarray] | None = None   # robot -> reference quaternion
    contacts: int = 0                                   # contacts with the station this tick
    contact_bodies: tuple[str, ...] = ()                # e.g. "bag-iss"
    touching: tuple[str, ...] = ()                      # bodies touching: robot_label()s, "bag"
    robot_clearance: float = float("nan")               # m, smallest over the robots
    bag_clearance: float = float("nan")                 # m (negative or nan: no bag)
    faults: dict[str, tuple[str, ...]] = field(default_factory=dict)   # robot -> active faults
    bag_robot_speed: float = float("nan")               # m/s, |v_bag - v_robot|
    effort: float = 0.0                                 # mean (wrench / limit)^2, 0..1


@dataclass
class Task:
    """A leg: goals per robot, tolerances, the time budget, what ends an episode, reward
    weights. Times count from `start_time` (sim s; None: the first sample's time)."""

    goals: dict[str, Goal]
    tolerance_position: float
    tolerance_attitude: float
    time_limit: float = NO_PLAN_LIMIT      # s: the budget (plan end + settle budget)
    end_on_contact: bool = False           # an episode ends at the first contact (RL)
    rest_speed: float = REST_SPEED         # m/s and rad/s under which a robot in tolerance
    rest_omega: float = REST_OMEGA         # is "at rest"
    rest_hold: float = REST_HOLD           # s every robot stays at rest: the goal is reached
    plan_end: float | None = None          # s: the leg does not end at rest before the plan's end
    settle_budget: float | None = None     # s of the budget beyond the plan (recorded)
    start_time: float | None = None        # sim s the leg starts (None: the first sample)
    weights: RewardWeights = field(default_factory=RewardWeights)
    name: str = ""

    @classmethod
    def from_scenario(cls, scenario: Any, plan_duration: float | None = None,
                      settle_budget: float = SETTLE_BUDGET, time_limit: float | None = None,
                      goals: dict[str, tuple[Any, Any]] | None = None,
                      flight_mode: str | None = None, **kw: Any) -> "Task":
        """The task of an astrobee.scenario.Scenario: its goal, its flight mode's tolerances,
        and a time budget of the plan's duration + settle_budget (or `time_limit`; 300 s
        without either). `goals` (robot -> (position, orientation)) replaces the scenario's."""
        mode = flight_modes.get(flight_mode or scenario.flight_mode or None)
        if goals is None:
            if scenario.goal_position is None:
                raise ValueError(f"scenario {scenario.name!r} has no goal")
            goals = formation_goals(scenario)
        built = {r: Goal(np.asarray(p, float).copy(), rot.normalize(np.asarray(q, float)))
                 for r, (p, q) in goals.items()}
        task = cls(built, float(mode.tolerance_pos), float(mode.tolerance_att),
                   name=scenario.name, **kw)
        if plan_duration is not None:
            task = task.with_plan(plan_duration, settle_budget)
        if time_limit is not None:
            task.time_limit = float(time_limit)
        return task

    def with_plan(self, plan_duration: float, settle_budget: float | None = None,
                  start_time: float | None = None) -> "Task":
        """This task for a plan of `plan_duration` s starting at `start_time` (sim s; None:
        the first sample): the budget is the plan's end + settle_budget (default: this task's,
        else SETTLE_BUDGET)."""
        settle = float(settle_budget if settle_budget is not None else
                       self.settle_budget if self.settle_budget is not None else SETTLE_BUDGET)
        if not (math.isfinite(settle) and settle >= 0):
            raise ValueError(f"settle_budget must be >= 0 s, got {settle:g}")
        plan = float(plan_duration)
        return replace(self, plan_end=plan, settle_budget=settle, time_limit=plan + settle,
                       start_time=self.start_time if start_time is None else float(start_time))

    def monitor(self) -> "TaskMonitor":
        return TaskMonitor(self)


def formation_goals(scenario: Any) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Goal pose of every robot: the scenario's goal for the first; the others keep their start
    pose relative to the first (a rigid formation)."""
    first = scenario.robots[0]
    p0, q0 = np.asarray(first.position, float), rot.normalize(np.asarray(first.orientation, float))
    pg = np.asarray(scenario.goal_position, float)
    qg = rot.normalize(np.asarray(scenario.goal_orientation, float))
    turn = rot.multiply(qg, rot.conjugate(q0))               # start -> goal rotation (world)
    out = {first.name: (pg, qg)}
    for r in scenario.robots[1:]:
        rel = np.asarray(r.position, float) - p0
        out[r.name] = (pg + rot.rotate(turn, rel),
                       rot.normalize(rot.multiply(turn, np.asarray(r.orientation, float))))
    return out


class TaskMonitor:
    """Figures of merit of a leg, updated one sample per tick (see the module docstring)."""

    def __init__(self, task: Task) -> None:
        self.task = task
        self.t0: float | None = None
        self.t = float("nan")
        self.samples = 0
        self._err_sq = 0.0
        self._err_n = 0
        self.max_position_error = float("nan")
        self.max_attitude_excursion = float("nan")          # rad, truth vs reference attitude
        self.min_robot_clearance = float("inf")
        self.min_bag_clearance = float("inf")
        self.contact_samples = 0
        self.contact_bodies: set[str] = set()
        self.touch_samples: dict[str, int] = {}             # body -> samples it touched
        self.robot_faults: dict[str, list[str]] = {}        # robot -> faults seen (in order)
        self.peak_bag_robot_speed = float("nan")
        self.time_to_goal: float | None = None              # first time every robot in tolerance
        self.time_to_rest: float | None = None              # when the rest that held began
        self.final: dict[str, tuple[float, float]] = {}     # robot -> (position, attitude error)
        self.speeds: dict[str, tuple[float, float] | None] = {}   # robot -> last (|v|, |w|)
        self.rest_since: dict[str, float | None] = {n: None for n in task.goals}
        self.at_rest = False                                # every robot at rest in tolerance now
        self.rested_at: float | None = None                 # s from the start: goal reached
        self.failure: str = ""                              # set by fail() (e.g. planning)
        self._dist = float("nan")
        self._prev_dist = float("nan")
        self._prev_t = float("nan")
        self._last_err = 0.0

    @property
    def elapsed(self) -> float:
        """s from the leg's start to the last sample."""
        return self.t - self.t0 if self.t0 is not None else float("nan")

    # ---- feeding --------------------------------------------------------------------------
    def update(self, s: TaskSample) -> None:
        """Take one tick's sample (times must not go back)."""
        if self.t0 is None:
            self.t0 = float(s.t) if self.task.start_time is None else float(self.task.start_time)
        self._prev_t, self.t = self.t, float(s.t)
        self.samples += 1
        self._judge_goal(s)
        self._last_err = 0.0
        for name, ref in (s.reference or {}).items():
            pose = s.poses.get(name)
            if pose is None:
                continue
            e = _norm(np.asarray(pose[0], float) - np.asarray(ref, float))
            self._err_sq += e * e
            self._err_n += 1
            self._last_err += e
            if not e <= self.max_position_error:
                self.max_position_error = e
        for name, q_ref in (s.reference_attitude or {}).items():
            pose = s.poses.get(name)
            if pose is not None:
                e = rot.angle_between(pose[1], q_ref)
                if not e <= self.max_attitude_excursion:
                    self.max_attitude_excursion = float(e)
        if math.isfinite(s.robot_clearance) and s.robot_clearance >= 0:
            self.min_robot_clearance = min(self.min_robot_clearance, float(s.robot_clearance))
        if math.isfinite(s.bag_clearance) and s.bag_clearance >= 0:
            self.min_bag_clearance = min(self.min_bag_clearance, float(s.bag_clearance))
        if s.contacts:
            self.contact_samples += 1
            self.contact_bodies.update(s.contact_bodies)
            for body in set(s.touching):
                self.touch_samples[body] = self.touch_samples.get(body, 0) + 1
        for robot, texts in s.faults.items():
            seen = self.robot_faults.setdefault(robot, [])
            seen += [f for f in texts if f not in seen]
        if math.isfinite(s.bag_robot_speed) and not s.bag_robot_speed <= self.peak_bag_robot_speed:
            self.peak_bag_robot_speed = float(s.bag_robot_speed)

    def _judge_goal(self, s: TaskSample) -> None:
        """Goal errors, speeds and the rest clock of every robot; the goal counts as reached
        once every robot has stayed in tolerance and at rest for rest_hold s (not before the
        plan's end)."""
        task = self.task
        dist = 0.0
        inside_all = True
        for name, goal in task.goals.items():
            pose = s.poses.get(name)
            if pose is None:
                inside_all = False
                self.rest_since[name] = None
                continue
            e_p = _norm(np.asarray(pose[0], float) - goal.position)
            e_a = rot.angle_between(pose[1], goal.orientation)
            self.final[name] = (e_p, e_a)
            dist += e_p
            inside = e_p <= task.tolerance_position and e_a <= task.tolerance_attitude
            inside_all = inside_all and inside
            v = (s.velocities or {}).get(name)
            speed = None if v is None else (_norm(v[0]), _norm(v[1]))
            self.speeds[name] = speed
            still = speed is not None and speed[0] < task.rest_speed and speed[1] < task.rest_omega
            if not (inside and still):
                self.rest_since[name] = None
            elif self.rest_since.get(name) is None:
                self.rest_since[name] = self.t
        self._prev_dist, self._dist = self._dist, dist
        if inside_all and self.time_to_goal is None:
            self.time_to_goal = self.elapsed
        since = [self.rest_since.get(n) for n in task.goals]
        self.at_rest = bool(since) and all(x is not None for x in since)
        if self.at_rest and self.rested_at is None:
            began = max(since)
            plan_over = task.plan_end is None or self.elapsed >= task.plan_end - 1e-9
            if self.t - began >= task.rest_hold - 1e-9 and plan_over:
                self.rested_at = self.elapsed
                self.time_to_rest = began - self.t0

    def fail(self, cause: str) -> None:
        """The leg failed for a reason the samples cannot show (no plan, no state...)."""
        self.failure = self.failure or cause

    def step(self, s: TaskSample) -> float:
        """update(s) and the reward of that tick."""
        self.update(s)
        return self.reward(s)

    # ---- judgement ------------------------------------------------------------------------
    @property
    def faults(self) -> list[str]:
        """Every fault seen, "<robot named>: text"."""
        return [f"{robot_named(r)}: {f}" for r, fs in self.robot_faults.items() for f in fs]

    def _rest_problem(self, name: str) -> str:
        """Why a robot in tolerance does not count as arrived: moving, or not at rest long
        enough; "" when it is at rest long enough."""
        speed = self.speeds.get(name)
        if speed is None:
            return "not at rest: no velocity measured"
        began = self.rest_since.get(name)
        if began is None:
            return f"not at rest: |v| {speed[0]:.3f} m/s, |w| {speed[1]:.3f} rad/s"
        held = self.t - began
        if held < self.task.rest_hold - 1e-9:
            return f"at rest for {held:.1f} s of the {self.task.rest_hold:g} s asked"
        return ""

    def robot_problems(self, name: str) -> list[str]:
        """What keeps one robot from success (the mission summary's wording): faults, its
        contact samples, final position and attitude error beyond the tolerance, or (within
        tolerance, the goal not reached) that it was not at rest."""
        out = []
        faults = self.robot_faults.get(name)
        if faults:
            out.append(f"fault: {'; '.join(faults)}")
        touched = self.touch_samples.get(robot_label(name), 0)
        if touched:
            out.append(f"{touched} contact samples")
        tol_p, tol_a = self.task.tolerance_position, self.task.tolerance_attitude
        e_p, e_a = self.final.get(name, (None, None))
        far = False
        if e_p is None or tol_p is None or not e_p <= tol_p:
            far = True
            out.append("final position error " + (f"{e_p:.3f} m > {tol_p} m" if e_p is not None
                                                  else "unknown (no pose)"))
        if e_a is None or tol_a is None or not e_a <= tol_a:
            far = True
            out.append("final attitude error " + (f"{e_a:.3f} rad > {tol_a} rad" if e_a is not None
                                                  else "unknown (no pose)"))
        if not far and not self.goal_reached:
            rest = self._rest_problem(name)
            if rest:
                out.append(rest)
        return out

    @property
    def goal_reached(self) -> bool:
        """Every robot stayed within tolerance of its goal and at rest for rest_hold s (after
        the plan's end): the leg is over."""
        return self.rested_at is not None

    @property
    def failed_early(self) -> bool:
        """A failure that ends an episode now: a fault, or a contact when the task says so."""
        return bool(self.failure or self.faults
                    or (self.task.end_on_contact and self.contact_samples))

    @property
    def terminated(self) -> bool:
        """The episode is over on its own terms: goal reached at rest, or failed."""
        return self.goal_reached or self.failed_early

    @property
    def truncated(self) -> bool:
        """The time budget ran out first."""
        return (not self.terminated and self.t0 is not None
                and self.elapsed >= self.task.time_limit - 1e-9)

    @property
    def over(self) -> bool:
        """The leg ends here: terminated or truncated."""
        return self.terminated or self.truncated

    def out_of_time(self) -> str:
        """Why the time ran out, in words: the budget ("time budget of 70.0 s (plan 40.0 s +
        settle 30 s) ran out before ...") or a limit given as such ("time limit of 2 s
        reached")."""
        t = self.task
        if (t.plan_end is None or t.settle_budget is None
                or abs(t.plan_end + t.settle_budget - t.time_limit) > 1e-9):
            return f"time limit of {t.time_limit:g} s reached"
        return (f"time budget of {t.time_limit:.1f} s (plan {t.plan_end:.1f} s + settle "
                f"{t.settle_budget:g} s) ran out before every robot was at rest at its goal")

    def verdict(self) -> tuple[bool, str]:
        """(success, cause) in the mission summary's words: 'goal reached', or why not: a
        failure before flight, the time budget, each robot's problems (named when there are
        several), the cargo bag's contacts."""
        parts = [self.failure] if self.failure else []
        if not self.task.goals and not self.failure:
            parts.append("no robot flown")
        elif self.samples == 0 and not self.failure:
            parts.append("no samples")
        if self.truncated:
            parts.append(self.out_of_time())
        goals = list(self.task.goals)
        for name in goals:
            probs = self.robot_problems(name)
            if probs and not self.failure:
                parts.append("; ".join(probs) if len(goals) == 1 else
                             f"{robot_named(name)}: {'; '.join(probs)}")
        cargo = self.touch_samples.get("bag", 0)
        if cargo:
            parts.append(f"cargo bag: {cargo} contact samples")
        ok = not parts
        return ok, "goal reached" if ok else "; ".join(parts)

    def reward(self, s: TaskSample) -> float:
        """Reward of the tick whose sample `s` was the last update (see RewardWeights)."""
        w = self.task.weights
        dt = self.t - self._prev_t if math.isfinite(self._prev_t) else 0.0
        r = 0.0
        if math.isfinite(self._prev_dist):
            r += w.progress * (self._prev_dist - self._dist)
        r -= w.tracking * self._last_err * dt
        if s.contacts:
            r -= w.contact
        clear = min([c for c in (s.robot_clearance, s.bag_clearance)
                     if math.isfinite(c) and c >= 0] or [float("inf")])
        if w.clearance_margin > 0 and clear < w.clearance_margin:
            r -= w.clearance * (w.clearance_margin - clear) / w.clearance_margin * dt
        r -= w.effort * float(s.effort) * dt
        if self.goal_reached:
            r += w.success
        elif self.failed_early or self.truncated:
            r -= w.failure
        return float(r)

    def metrics(self) -> dict[str, Any]:
        """The leg's figures as a flat dict (nan/None where not measured)."""
        nan = float("nan")
        fin = list(self.final.values())
        speeds = [v for v in self.speeds.values() if v is not None]
        out: dict[str, Any] = {
            "rms_position_error": math.sqrt(self._err_sq / self._err_n) if self._err_n else nan,
            "max_position_error": self.max_position_error,
            "max_attitude_excursion": self.max_attitude_excursion,
            "final_position_error": max((e[0] for e in fin), default=nan),
            "final_attitude_error": max((e[1] for e in fin), default=nan),
            "final_speed": max((v[0] for v in speeds), default=nan),
            "final_omega": max((v[1] for v in speeds), default=nan),
            "min_robot_clearance": (self.min_robot_clearance
                                    if math.isfinite(self.min_robot_clearance) else nan),
            "min_bag_clearance": (self.min_bag_clearance
                                  if math.isfinite(self.min_bag_clearance) else nan),
            "contacts": self.contact_samples,
            "contact_bodies": ",".join(sorted(self.contact_bodies)),
            "faults": len(self.faults),
            "peak_bag_robot_speed": self.peak_bag_robot_speed,
            "time_to_goal": nan if self.time_to_goal is None else self.time_to_goal,
            "time_to_rest": nan if self.time_to_rest is None else self.time_to_rest,
            "time_budget": self.task.time_limit,
            "settle_budget": nan if self.task.settle_budget is None else self.task.settle_budget,
            "duration": self.elapsed,
        }
        if len(self.task.goals) > 1:
            for name, (e_p, e_a) in self.final.items():
                out[f"final_position_error_{robot_label(name)}"] = e_p
                out[f"final_attitude_error_{robot_label(name)}"] = e_a
        return out


def judge(task: Task, samples: Iterable[TaskSample], failure: str = "") -> TaskMonitor:
    """A monitor fed with a leg's samples (in time order) until the Task ends the leg: the one
    judgement of the mission, recorded bags and studies (`failure`: why the leg was cut short,
    e.g. a lost node)."""
    monitor = task.monitor()
    if failure:
        monitor.fail(failure)
    for s in samples:
        monitor.update(s)
        if monitor.goal_reached or monitor.truncated:
            break
    return monitor
