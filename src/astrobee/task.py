"""What success, failure and reward mean for one cargo-transport leg (transport-free).

A `Task` holds the goal of every robot, the flight mode's goal tolerances and a time limit; a
`TaskMonitor` is fed one `TaskSample` per control tick (live from an in-process flight or an
environment, or read back from a recorded bag) and keeps the leg's figures of merit. Its
`verdict()` is the mission's rule: a leg succeeds when every robot ends within the position and
attitude tolerance of its goal, with no contact with the station and no fault, before the time
limit; the cause names what failed and on which robot. `reward()` is the same judgement made
dense for reinforcement learning (progress toward the goal, tracking, contact, low clearance,
effort; a terminal bonus or penalty).

Multi-robot: the scenario's goal is the first robot's; every other robot keeps its start pose
relative to the first (the formation moves rigidly), unless goals are given explicitly.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import flight_modes
from . import rotations as rot

REST_SPEED = 0.01      # m/s: "at rest" (the PD law's STOPPED test)
REST_OMEGA = 0.02      # rad/s
TIME_MARGIN = 10.0     # s of time limit beyond the plan and the settle time


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
    """A leg: goals per robot, tolerances, time limit, what ends an episode, reward weights."""

    goals: dict[str, Goal]
    tolerance_position: float
    tolerance_attitude: float
    time_limit: float = 300.0              # sim s from the first sample
    end_on_contact: bool = False           # an episode ends at the first contact (RL)
    rest_speed: float = REST_SPEED         # m/s and rad/s under which a robot in tolerance
    rest_omega: float = REST_OMEGA         # is "at rest": the goal is reached
    weights: RewardWeights = field(default_factory=RewardWeights)
    name: str = ""

    @classmethod
    def from_scenario(cls, scenario: Any, plan_duration: float | None = None,
                      settle_time: float = 5.0, time_limit: float | None = None,
                      goals: dict[str, tuple[Any, Any]] | None = None,
                      flight_mode: str | None = None, **kw: Any) -> "Task":
        """The task of an astrobee.scenario.Scenario: its goal, its flight mode's tolerances,
        and a time limit of the plan's duration + settle_time + 10 s (or `time_limit`; 300 s
        without either). `goals` (robot -> (position, orientation)) replaces the scenario's."""
        mode = flight_modes.get(flight_mode or scenario.flight_mode or None)
        if goals is None:
            if scenario.goal_position is None:
                raise ValueError(f"scenario {scenario.name!r} has no goal")
            goals = formation_goals(scenario)
        built = {r: Goal(np.asarray(p, float).copy(), rot.normalize(np.asarray(q, float)))
                 for r, (p, q) in goals.items()}
        if time_limit is None:
            time_limit = (plan_duration + settle_time + TIME_MARGIN if plan_duration is not None
                          else 300.0)
        return cls(built, float(mode.tolerance_pos), float(mode.tolerance_att),
                   float(time_limit), name=scenario.name, **kw)

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
        self.min_robot_clearance = float("inf")
        self.min_bag_clearance = float("inf")
        self.contact_samples = 0
        self.contact_bodies: set[str] = set()
        self.touch_samples: dict[str, int] = {}             # body -> samples it touched
        self.robot_faults: dict[str, list[str]] = {}        # robot -> faults seen (in order)
        self.peak_bag_robot_speed = float("nan")
        self.time_to_goal: float | None = None
        self.final: dict[str, tuple[float, float]] = {}     # robot -> (position, attitude error)
        self.at_rest = False
        self.failure: str = ""                              # set by fail() (e.g. planning)
        self._dist = float("nan")
        self._prev_dist = float("nan")
        self._prev_t = float("nan")
        self._last_err = 0.0

    # ---- feeding --------------------------------------------------------------------------
    def update(self, s: TaskSample) -> None:
        """Take one tick's sample (times must not go back)."""
        if self.t0 is None:
            self.t0 = s.t
        self._prev_t, self.t = self.t, float(s.t)
        self.samples += 1
        tol_p, tol_a = self.task.tolerance_position, self.task.tolerance_attitude
        dist = 0.0
        inside = True
        for name, goal in self.task.goals.items():
            pose = s.poses.get(name)
            if pose is None:
                inside = False
                continue
            e_p = _norm(np.asarray(pose[0], float) - goal.position)
            e_a = rot.angle_between(pose[1], goal.orientation)
            self.final[name] = (e_p, e_a)
            dist += e_p
            inside = inside and e_p <= tol_p and e_a <= tol_a
        self._prev_dist, self._dist = self._dist, dist
        if inside and self.time_to_goal is None:
            self.time_to_goal = self.t - self.t0
        rest = inside
        if s.velocities is not None:
            for name in self.task.goals:
                v = s.velocities.get(name)
                if v is None or not (_norm(v[0]) < self.task.rest_speed
                                     and _norm(v[1]) < self.task.rest_omega):
                    rest = False
        else:
            rest = False
        self.at_rest = rest
        self._last_err = 0.0
        if s.reference:
            for name, ref in s.reference.items():
                pose = s.poses.get(name)
                if pose is None:
                    continue
                e = _norm(np.asarray(pose[0], float) - np.asarray(ref, float))
                self._err_sq += e * e
                self._err_n += 1
                self._last_err += e
                if not e <= self.max_position_error:
                    self.max_position_error = e
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

    @classmethod
    def from_figures(cls, task: Task, final: dict[str, tuple[float | None, float | None]],
                     contacts: dict[str, int] | None = None,
                     faults: dict[str, list[str]] | None = None,
                     failure: str = "") -> "TaskMonitor":
        """A monitor holding a leg's end figures instead of its samples (what the mission's
        summary keeps): final (position, attitude) error per robot (None: no pose), contact
        samples per touching body (robot_label()s, "bag"), faults per robot, a failure that
        ended the leg. verdict() and robot_problems() then judge them."""
        m = cls(task)
        m.samples, m.t0, m.t = 1, 0.0, 0.0
        m.final = {n: e for n, e in final.items()}
        m.touch_samples = {b: int(n) for b, n in (contacts or {}).items() if n}
        m.contact_samples = max(m.touch_samples.values(), default=0)
        m.robot_faults = {r: list(f) for r, f in (faults or {}).items() if f}
        m.failure = failure
        return m

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

    def robot_problems(self, name: str) -> list[str]:
        """What keeps one robot from success (the mission summary's wording): faults, its
        contact samples, final position and attitude error beyond the tolerance."""
        out = []
        faults = self.robot_faults.get(name)
        if faults:
            out.append(f"fault: {'; '.join(faults)}")
        touched = self.touch_samples.get(robot_label(name), 0)
        if touched:
            out.append(f"{touched} contact samples")
        tol_p, tol_a = self.task.tolerance_position, self.task.tolerance_attitude
        e_p, e_a = self.final.get(name, (None, None))
        if e_p is None or tol_p is None or not e_p <= tol_p:
            out.append("final position error " + (f"{e_p:.3f} m > {tol_p} m" if e_p is not None
                                                  else "unknown (no pose)"))
        if e_a is None or tol_a is None or not e_a <= tol_a:
            out.append("final attitude error " + (f"{e_a:.3f} rad > {tol_a} rad" if e_a is not None
                                                  else "unknown (no pose)"))
        return out

    @property
    def goal_reached(self) -> bool:
        """Every robot within tolerance of its goal and at rest, at the last sample."""
        return self.at_rest

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
        """The time limit ran out first."""
        return (not self.terminated and self.t0 is not None
                and self.t - self.t0 >= self.task.time_limit - 1e-9)

    def verdict(self) -> tuple[bool, str]:
        """(success, cause) in the mission summary's words: 'goal reached', or why not: a
        failure before flight, the time limit, each robot's problems (named when there are
        several), the cargo bag's contacts."""
        parts = [self.failure] if self.failure else []
        if not self.task.goals and not self.failure:
            parts.append("no robot flown")
        elif self.samples == 0 and not self.failure:
            parts.append("no samples")
        if self.truncated:
            parts.append(f"time limit of {self.task.time_limit:g} s reached")
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
        fin = list(self.final.values())
        out: dict[str, Any] = {
            "rms_position_error": math.sqrt(self._err_sq / self._err_n) if self._err_n else float("nan"),
            "max_position_error": self.max_position_error,
            "final_position_error": max((e[0] for e in fin), default=float("nan")),
            "final_attitude_error": max((e[1] for e in fin), default=float("nan")),
            "min_robot_clearance": (self.min_robot_clearance
                                    if math.isfinite(self.min_robot_clearance) else float("nan")),
            "min_bag_clearance": (self.min_bag_clearance
                                  if math.isfinite(self.min_bag_clearance) else float("nan")),
            "contacts": self.contact_samples,
            "contact_bodies": ",".join(sorted(self.contact_bodies)),
            "faults": len(self.faults),
            "peak_bag_robot_speed": self.peak_bag_robot_speed,
            "time_to_goal": float("nan") if self.time_to_goal is None else self.time_to_goal,
            "duration": (self.t - self.t0) if self.t0 is not None else float("nan"),
        }
        if len(self.task.goals) > 1:
            for name, (e_p, e_a) in self.final.items():
                out[f"final_position_error_{robot_label(name)}"] = e_p
                out[f"final_attitude_error_{robot_label(name)}"] = e_a
        return out
