"""One mission leg, phase by phase: bring the sim to the scenario, wait for the robots and their
controllers, plan, hand the segments over with one start stamp, then follow the flight until
the Task ends it (every robot at rest at its goal for the rest hold, or the time budget out:
plan end + settle budget) or a fault or a lost peer aborts it. The controllers' own STOPPED
ends nothing: they keep holding their goal until told otherwise."""
from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from astrobee import flight_modes
from astrobee import msgconv as mc
from astrobee import rotations as rot
from astrobee.leg_samples import LegSamples
from astrobee.task import Goal, Task, TaskMonitor

from .planning import HANDOVER_LEAD, plan_formation, plan_one
from .progress import Progress
from .result import Interrupted, LegResult, MissionError, finish_leg
from .watch import FAULT_WATCH_SIM, FAULT_WATCH_WALL, IDLE, STOPPED, RobotWatch

NAMES = mc.MotionState.NAMES
MAX_RESUME_STEPS = 100_000     # sim_node's bound on one /sim/control request
CHUNK_STEPS = 350              # deterministic runs: physics steps per chunk (1 s at 350 Hz)


def fly_leg(client: Any, name: str, reset: bool, progress: Progress, wall_timeout: float,
            ready_timeout: float, settle_budget: float) -> LegResult:
    """Fly one scenario to its goal; the result says how it went (never raises MissionError)."""
    res = LegResult(scenario=name, settle_budget=settle_budget)
    wall0 = time.monotonic()
    client._goals, client._starts = {}, {}
    client.task, client.start_ns, client.leg = None, None, None
    leg = Leg(client, name, progress, res, wall_timeout, ready_timeout, settle_budget)
    try:
        leg.fly(reset)
    except MissionError as exc:
        res.success, res.reason = False, str(exc)
    except Interrupted:
        res.success, res.reason = False, "interrupted (SIGINT/SIGTERM)"
        client.interrupted_result = res
        raise
    finally:
        res.wall_time = time.monotonic() - wall0
        if res.wall_t0 is not None and res.wall_t1 is None:
            res.wall_t1 = time.time()
        finish_leg(client, res, leg.end_ns)
        for w in client.watches.values():      # what comes now belongs to no leg
            w.leg = None
        client.leg = None
    return res


class Leg:
    """The state of one leg while it flies (see the module docstring)."""

    def __init__(self, client: Any, name: str, progress: Progress, res: LegResult,
                 wall_timeout: float, ready_timeout: float, settle_budget: float) -> None:
        self.c = client
        self.name = name
        self.progress = progress
        self.res = res
        self.wall_timeout = wall_timeout
        self.ready_timeout = ready_timeout
        self.settle_budget = settle_budget
        self.ws: list[RobotWatch] = []
        self.marks: dict[str, int] = {}
        self.monitor: TaskMonitor | None = None   # live: decides when the leg ends
        self.end_ns: int | None = None            # stamp of the sample that ended it
        self.fault_seen: dict[str, float] = {}
        self.duration = math.nan
        self.t_sent = math.nan
        self.wall_sent = math.nan

    def fly(self, reset: bool) -> None:
        info, fm, goal = self._scenario(reset)
        self._robots(info)
        segments = self._plan(info, fm, goal)
        self._hand_over(segments)
        self._await_control()
        if self.c.handover:       # every controller holds its segment: the sim may run
            self._run_chunks()
        else:
            self.c.spin_until(self._finished, self.wall_timeout, "the end of the flight",
                              self._tick)
        self._account()

    # ---- before the flight ----------------------------------------------------------------
    def _scenario(self, reset: bool) -> tuple[Any, Any, tuple[np.ndarray, np.ndarray]]:
        """The sim brought to the scenario; (ScenarioInfo as built, flight mode, goal)."""
        c, name, res = self.c, self.name, self.res
        if c.handover:
            self.progress.update(f"[mission] {name}: waiting for the graph, then the sim's reset")
            c._paused_reset(name, self.ready_timeout)
            reset = False
        if not reset and (c.scenario_info is None or c.scenario_info.name != name):
            c.spin_until(lambda: c.scenario_info is not None, self.ready_timeout,
                         "the simulator's scenario (/sim/scenario)")
            if c.scenario_info.name != name:
                reset = True      # the sim runs another scenario: bring it to this one
        if reset:
            c.reset_to(name, self.ready_timeout)
        # the scenario as the simulator built it (launch overrides included)
        c.spin_until(lambda: c.scenario_info is not None and c.scenario_info.name == name,
                     self.ready_timeout, f"the simulator's description of {name} (/sim/scenario)")
        info = c.scenario_info
        fm = flight_modes.get(info.flight_mode or None)
        res.flight_mode = fm.name
        res.tolerance_position, res.tolerance_attitude = fm.tolerance_pos, fm.tolerance_att
        res.carrying_bag = bool(info.carrying_bag)
        if not info.has_goal:
            raise MissionError(f"scenario {name} has no goal")
        goal_p, goal_q = mc.pose(info.goal)
        goal_q = rot.normalize(goal_q)
        res.goal = [*goal_p.tolist(), *goal_q.tolist()]
        return info, fm, (goal_p, goal_q)

    def _robots(self, info: Any) -> None:
        """The leg's robots, each at its start with its controller ready; their start poses."""
        c, name = self.c, self.name
        names = list(info.robots)
        if len(names) == 1 and c.ns and names != [c.ns]:
            raise MissionError(f"scenario {name} has no robot {c.ns!r}: robots {names}")
        if not names or len(names) > 2:
            raise MissionError(f"scenario {name} has {len(names)} robots: the mission flies one "
                               f"robot, or two carrying a cargo bag in formation")
        c.flying = names
        self.ws = ws = [c.watch(n) for n in names]
        self.starts = {n: mc.pose(info.starts[i])[0] for i, n in enumerate(names)}
        self.progress.update(f"[mission] {name}: waiting for the robots' states and controllers"
                             if len(ws) > 1 else
                             f"[mission] {name}: waiting for the robot's state and the controller")
        c.spin_until(lambda: not self._not_ready(), self.ready_timeout,
                     lambda: f"the robots at the start of {name} and their controllers ready "
                             f"({self._not_ready()})")
        c.watch_peers(ws)
        for w in ws:
            pos, q = w.pose
            c._starts[w.name] = [*pos.tolist(), *q.tolist()]
        self.res.start = c._starts[names[0]]

    def _not_ready(self) -> str:
        """Which robots are not at their start with a controller holding ("" when all are)."""
        def why(w: RobotWatch) -> str:
            if w.pose is None:
                return "no pose"
            if float(np.linalg.norm(w.pose[0] - self.starts[w.name])) >= 0.5:
                return "not at its start"
            if w.mob_state not in (IDLE, STOPPED):
                return (f"no controller ready ({mc.robot_topic(w.name, mc.MOB_STATE)}: "
                        f"{NAMES.get(w.mob_state, w.mob_state)})")
            return ""
        return "; ".join(f"{w.named}: {why(w)}" for w in self.ws if why(w))

    def _plan(self, info: Any, fm: Any, goal: tuple[np.ndarray, np.ndarray]) -> list[Any]:
        """The segments of the leg (one per robot) and its plan duration."""
        c, ws = self.c, self.ws
        c._goals = {ws[0].name: goal}
        self.progress.update(f"[mission] {self.name}: planning")
        if len(ws) == 1:
            segments, self.duration = plan_one(c, ws[0], info, fm, *goal, self.res)
        else:
            segments, self.duration = plan_formation(c, ws, info, fm, *goal, self.res)
        self.res.plan_duration = self.duration
        self.first_when = mc.stamp_ns(segments[0].segment[0].when) * 1e-9 \
            if segments and segments[0].segment else -math.inf
        return segments

    # ---- the flight -----------------------------------------------------------------------
    def _hand_over(self, segments: list[Any]) -> None:
        """Every robot's messages go to the leg's samples from now; the segments published
        (one start stamp for all: formation plans)."""
        c = self.c
        c.leg = LegSamples([w.name for w in self.ws])
        self.marks = {w.name: w.start_leg(c.leg) for w in self.ws}
        self.t_sent = c.sim_time
        self.res.sim_t0 = self.t_sent
        self.wall_sent = time.monotonic()
        self.res.wall_t0 = time.time()
        for w, seg in zip(self.ws, segments):
            w.seg_pub.publish(seg)

    def _await_control(self) -> None:
        """Wait until every controller follows its segment (a controller that dies before its
        CONTROLLING state reaches us shows up as the sim's watchdog fault: stop waiting then,
        too); the leg's Task starts when the segment does."""
        c, ws = self.c, self.ws
        c.spin_until(lambda: all(w.controlling_since(self.marks[w.name]) is not None for w in ws)
                     or self._faulted(), 30.0,
                     lambda: "the controllers to accept their segments (" + ", ".join(
                         w.named for w in ws if w.controlling_since(self.marks[w.name]) is None)
                     + " did not)", self._tick)
        accepted = [t for t in (w.controlling_since(self.marks[w.name]) for w in ws) if t is not None]
        self.t_acc = max(min(accepted, default=self.t_sent), self.first_when)
        goals = {n: Goal(np.asarray(p, float), rot.normalize(np.asarray(q, float)))
                 for n, (p, q) in c._goals.items()}
        c.task = Task(goals, self.res.tolerance_position, self.res.tolerance_attitude,
                      name=self.name).with_plan(self.duration, self.settle_budget, self.t_acc)
        c.start_ns = mc.to_ns(self.t_acc)
        self.monitor = c.task.monitor()

    def _feed(self) -> None:
        """The live monitor takes the samples complete so far; the leg's end is the first at
        which the Task says it is over (goal reached at rest, or the budget out)."""
        if self.monitor is None or self.end_ns is not None or self.c.leg is None:
            return
        for s in self.c.leg.new_samples(self.c.start_ns):
            self.monitor.update(s)
            if self.monitor.goal_reached or self.monitor.truncated:
                self.end_ns = mc.to_ns(s.t)
                return

    def _faulted(self) -> bool:
        """A fault arrived during the flight and the robots were watched for a while since."""
        c = self.c
        if not any(w.faults for w in self.ws):
            return False
        if not self.fault_seen:
            self.fault_seen.update(sim=c.sim_time, wall=time.monotonic())
        return (c.sim_time - self.fault_seen["sim"] >= FAULT_WATCH_SIM
                or time.monotonic() - self.fault_seen["wall"] >= FAULT_WATCH_WALL)

    def _finished(self) -> bool:
        return self._faulted() or self.end_ns is not None

    def _tick(self) -> None:
        """Feed the live monitor; the progress line."""
        self._feed()
        c, ws = self.c, self.ws
        errs = "  ".join((f"{w.label} " if len(ws) > 1 else "") + "err "
                         + (f"{w.series.pos_error[-1]:.3f} m" if w.series.pos_error else "-")
                         for w in ws)
        s = c.series
        clear = s.robot_clearance[-1] if s.robot_clearance else float("nan")
        el = c.sim_time - self.t_sent
        wall = time.monotonic() - self.wall_sent
        rtf = el / wall if wall > 0 else float("nan")
        state = "/".join(NAMES.get(w.mob_state, str(w.mob_state)) for w in ws)
        self.progress.update(f"[mission] {self.name}: {state} t={el:5.1f}/{self.duration:.1f} s  "
                             f"{errs}  clear {clear:.2f} m  {rtf:4.1f}x real time")

    def _run_chunks(self) -> None:
        """Deterministic lockstep: resume for the plan's duration, then a chunk at a time, until
        a chunk ends with the leg over (or a fault) before its last tick. The sim pauses at each
        chunk's end; the samples are read once every controller has answered the last tick, so
        the leg ends at a tick the flight fixes, whatever the wall clock."""
        c, ws = self.c, self.ws
        deadline = time.monotonic() + self.wall_timeout
        first = HANDOVER_LEAD + self.duration + 1.0      # the lead, the plan and a second
        steps = min(int(math.ceil(first * CHUNK_STEPS)), MAX_RESUME_STEPS)
        while True:
            resp = c._control(mc.SimControl.RESUME, steps, 30.0, "resume")
            t_end = mc.stamp_ns(resp.sim_time)
            # the last tick's answers, its pose and twist: under load the state of t_end can
            # come after the controllers' answers to it (another publisher, another path)
            c.spin_until(lambda: all(w.cmd_ns >= t_end and w.sim_time == w.sim_time
                                     and mc.to_ns(w.sim_time) >= t_end for w in ws)
                         and c.leg.complete(t_end),
                         max(1.0, deadline - time.monotonic()), "the end of the flight",
                         self._tick)
            # everything received before the last tick's answers (the states and faults of
            # earlier ticks) runs now: the executor serves topics in turn, not in the order
            # they came
            while c.node.spin_once(timeout_sec=0):
                pass
            self._feed()
            t = t_end * 1e-9
            if self.end_ns is not None or any(f < t - 1e-9 for w in ws for f, _ in w.faults):
                if any(w.faults for w in ws):
                    self.fault_seen.update(sim=c.sim_time, wall=time.monotonic())
                return
            steps = CHUNK_STEPS

    def _account(self) -> None:
        """Times of the leg; a fault during it aborts it (named)."""
        c, ws, res = self.c, self.ws, self.res
        res.sim_t1, res.wall_t1 = c.sim_time, time.time()
        res.sim_time = c.sim_time - self.t_sent
        if self.fault_seen:
            first = min(((w.faults[0][0], w) for w in ws if w.faults), key=lambda x: x[0])[1]
            raise MissionError(f"flight aborted on a fault of {first.named}: {first.faults[0][1]}"
                               if len(ws) > 1 else f"flight aborted on a fault: {first.faults[0][1]}")
        end = self.end_ns * 1e-9 if self.end_ns is not None else c.sim_time
        res.duration = end - self.t_acc
        wall = time.monotonic() - self.wall_sent
        res.real_time_factor = res.sim_time / wall if wall > 0 else None
