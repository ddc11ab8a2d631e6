"""What a mission leg produces: its LegResult (summary.json's legs[i]), the Task's judgement of
the leg's samples (finish_leg: astrobee.task decides, on truth) and the run's outputs
(summary.json written atomically, one plot per leg)."""
from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from astrobee import config
from astrobee import rotations as rot
from astrobee.task import Goal, Task, TaskMonitor, judge
from astrobee_bringup import summary as sm
from astrobee_bringup.leg_plot import plot
from astrobee_bringup.series import Series, contact_name


class Interrupted(Exception):
    """SIGINT/SIGTERM arrived while flying."""


class MissionError(Exception):
    """A leg could not be flown (no planner, plan failed, no state...): the message says why."""


@dataclass
class LegResult:
    scenario: str
    success: bool = False
    reason: str = ""
    flight_mode: str = ""
    carrying_bag: bool = False
    carry_extent: float = 0.0                # m of planning margin for the cargo bag
    start: list[float] = field(default_factory=list)
    goal: list[float] = field(default_factory=list)
    planning_time: float | None = None
    plan_duration: float | None = None
    duration: float | None = None            # sim s from segment accepted to the leg's end
    settle_budget: float | None = None       # s the leg may run past the plan's end
    time_budget: float | None = None         # s: plan + settle budget (from the leg's start)
    time_to_rest: float | None = None        # s from the start to the rest that held
    final_position_error: float | None = None
    final_attitude_error: float | None = None
    final_speed: float | None = None         # m/s, |v| (truth) at the leg's end, largest robot
    final_omega: float | None = None         # rad/s, |w|
    tolerance_position: float | None = None
    tolerance_attitude: float | None = None
    rms_position_error: float | None = None
    max_position_error: float | None = None
    max_attitude_error: float | None = None
    max_attitude_excursion: float | None = None   # rad, truth attitude vs the reference
    min_robot_clearance: float | None = None
    min_bag_clearance: float | None = None
    contacts: int = 0
    contact_bodies: list[str] = field(default_factory=list)
    faults: list[str] = field(default_factory=list)
    sim_time: float | None = None
    wall_time: float | None = None
    real_time_factor: float | None = None
    sim_t0: float | None = None
    sim_t1: float | None = None
    wall_t0: float | None = None            # wall clock (s since the epoch) of the flight,
    wall_t1: float | None = None            # to find the leg in the recording (sim time restarts)
    robots: list[dict[str, Any]] = field(default_factory=list)   # summary.RobotResult per robot
    plot: str = ""
    realism: dict[str, Any] = field(default_factory=dict)      # knobs on (sim's /sim/realism)
    disturbances: list[dict[str, Any]] = field(default_factory=list)   # pulses applied


def _finite(v: Any) -> float | None:
    return float(v) if v is not None and math.isfinite(float(v)) else None


def leg_task(client: Any, res: LegResult) -> Task:
    """The Task of the leg being flown: each robot's goal, the flight mode's tolerances, the
    plan and its start when known (client.task once the leg flies)."""
    if getattr(client, "task", None) is not None:
        return client.task
    goals = {n: Goal(np.asarray(p, float), rot.normalize(np.asarray(q, float)))
             for n, (p, q) in client._goals.items()}
    return Task(goals, res.tolerance_position, res.tolerance_attitude, name=res.scenario)


def finish_leg(client: Any, res: LegResult, end_ns: int | None = None) -> TaskMonitor:
    """Judge the leg (the Task fed with its samples from the leg's start to `end_ns`; an abort
    already in res.reason is the failure) and fill res and its per-robot results."""
    ws = [client.watches[n] for n in client.flying]
    s = client.series
    for k, v in s.tracking().items():
        setattr(res, k, v if v == v else None)
    cl = s.clearance()
    res.min_robot_clearance, res.min_bag_clearance = cl["min_robot_clearance"], cl["min_bag_clearance"]
    res.contacts = cl["contact_samples"]
    res.contact_bodies = sorted(s.contact_bodies)
    task = leg_task(client, res)
    start = getattr(client, "start_ns", None)
    samples = [] if client.leg is None or start is None else client.leg.samples(start, end_ns)
    aborted = res.reason
    monitor = judge(task, samples, aborted)
    robots = []
    for w in ws:
        r = sm.RobotResult(name=w.name, start=client._starts.get(w.name, []))
        goal = client._goals.get(w.name)
        if goal is not None:
            r.goal = [*goal[0].tolist(), *rot.normalize(goal[1]).tolist()]
            if w.name in monitor.final:
                r.final_position_error, r.final_attitude_error = map(float, monitor.final[w.name])
            elif w.pose is not None:
                r.final_position_error = float(np.linalg.norm(w.pose[0] - goal[0]))
                r.final_attitude_error = float(rot.angle_between(w.pose[1], rot.normalize(goal[1])))
                monitor.final[w.name] = (r.final_position_error, r.final_attitude_error)
        for k, v in w.series.tracking().items():
            setattr(r, k, v if v == v else None)
        r.min_clearance = w.series.robot_min_clearance()
        r.contacts = s.contact_samples(contact_name(w.name))
        r.faults = [text for _, text in w.faults]
        probs = monitor.robot_problems(w.name) if w.name in task.goals else ["no goal"]
        r.reached_goal = not any(p.startswith("final") for p in probs)
        r.success = not probs
        r.reason = "goal reached" if not probs else "; ".join(probs)
        robots.append(r)
    res.success, res.reason = monitor.verdict()
    if not robots:
        res.success, res.reason = False, aborted or "no robot flown"
    _failure_marks(ws, robots, s, aborted)
    m = monitor.metrics()
    res.settle_budget = task.settle_budget
    res.time_budget = task.time_limit if task.plan_end is not None else None
    res.time_to_rest = _finite(m["time_to_rest"])
    res.max_attitude_excursion = _finite(m["max_attitude_excursion"])
    res.final_speed, res.final_omega = _finite(m["final_speed"]), _finite(m["final_omega"])
    res.robots = [asdict(r) for r in robots]
    res.realism = dict(client.realism.get("knobs") or {})
    res.disturbances = list(client.realism.get("applied") or [])
    res.faults = [text if len(ws) == 1 else f"{w.named}: {text}"
                  for w in ws for _, text in w.faults]
    if robots:
        errs = [r.final_position_error for r in robots]
        atts = [r.final_attitude_error for r in robots]
        res.final_position_error = None if None in errs else max(errs)
        res.final_attitude_error = None if None in atts else max(atts)
        rms = [r.rms_position_error for r in robots if r.rms_position_error is not None]
        res.rms_position_error = max(rms) if rms else None
    return monitor


def _failure_marks(ws: list[Any], robots: list[sm.RobotResult], s: Series, aborted: str) -> None:
    """Where and why each failing robot failed (the plot's marks)."""
    for w, r in zip(ws, robots):
        if r.success:
            continue
        if w.faults:
            t, why = w.faults[0][0], f"fault: {w.faults[0][1]}"
        elif r.contacts:
            t, why = s.first_contact(contact_name(w.name)), "touched the station"
        elif aborted:       # not the cause: it stopped with the leg
            r.reason = f"stopped with the aborted leg ({r.reason})"
            continue
        else:
            t, why = w.sim_time, r.reason
        if t is not None and t == t:
            r.failed_at = {"t": t, "position": w.position_at(t), "why": why}


def _plain(v: Any) -> Any:
    """JSON-ready: numpy numbers as Python's, non-finite floats as null."""
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, set)):
        return [_plain(x) for x in v]
    if isinstance(v, np.ndarray):
        return _plain(v.tolist())
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(float(v)) else None
    if isinstance(v, np.integer):
        return int(v)
    return v


def write_summary(path: Path, data: dict[str, Any]) -> str:
    """Write summary.json atomically: a temporary file in the same folder, then renamed over
    it (a reader sees the old file or the new one, never half of one; a failed write leaves
    no temporary behind). Returns "" or the failure in one line."""
    path = Path(path)
    tmp = None
    try:
        text = json.dumps(_plain(data), indent=2) + "\n"
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        with os.fdopen(fd, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
        return ""
    except (OSError, TypeError, ValueError) as exc:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
        return f"could not write {path}: {exc}"


def write_outputs(run_dir: Path, legs: list[LegResult], series: list[dict[str, Series]],
                  status: str) -> dict[str, Any]:
    """summary.json and one plot per leg (every robot of the leg) in run_dir; data["write_error"]
    says in one line why summary.json could not be written."""
    run_dir.mkdir(parents=True, exist_ok=True)
    boxes = config.keep_in_boxes()
    for leg, per in zip(legs, series):
        if any(s.position for s in per.values()):
            name = "plot.png" if len(legs) == 1 else f"plot_{leg.scenario}.png"
            try:
                plot(per, run_dir / name, boxes,
                        title=f"{leg.scenario}: {'SUCCESS' if leg.success else 'FAILED'}: {leg.reason}",
                        start=leg.start[:3] or None, goal=leg.goal[:3] or None,
                        robots=leg.robots or None, t0=leg.sim_t0, success=leg.success)
                leg.plot = name
            except Exception as exc:  # noqa: BLE001 - a plot failure must not lose the summary
                leg.plot = f"plot failed: {exc}"
    dicts = [asdict(l) for l in legs]
    ok, reason = sm.run_verdict(dicts)
    data = {"success": ok, "status": status, "legs": dicts}
    if len(legs) == 1:
        data.update({k: v for k, v in dicts[0].items() if k not in data})
    else:
        data["reason"] = reason
    data["faults"] = [f"{l.scenario}: {f}" for l in legs for f in l.faults] if len(legs) > 1 \
        else data.get("faults", [])
    err = write_summary(run_dir / "summary.json", data)
    if err:
        data["write_error"] = err
    return data
