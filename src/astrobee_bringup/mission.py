"""The mission client: plan a scenario's route, hand it to the controller, follow it to the end
and write the run's summary.json and plot.

    python -m astrobee_bringup.mission --scenario node2_to_jem --run-dir runs/X [--scenario node2_to_jem_bag]

With several scenarios (the demo) the legs fly one after the other in the same graph, the
simulation reset to each leg's scenario (/sim/reset) before it. Exit status: 0 when every leg
succeeded, 1 when one failed, 2 for a bad argument, 130 when interrupted (SIGINT/SIGTERM).
The launch description runs it as one of its processes (see astrobee_bringup/launch/cargo_transport.py).
"""
from __future__ import annotations

import argparse
import signal
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from astrobee import config, flight_modes
from astrobee import msgconv as mc
from astrobee import rotations as rot
from astrobee.scenario import Scenario, ScenarioError
from astrobee_bringup import summary as sm

IDLE, STOPPED, STOPPING, CONTROLLING = (mc.MotionState.IDLE, mc.MotionState.STOPPED,
                                        mc.MotionState.STOPPING, mc.MotionState.CONTROLLING)
NAMES = mc.MotionState.NAMES


# After a fault (the sim's propulsion watchdog: the controller is gone) the leg ends once the
# robot has been watched coasting this long (sim s), or this many wall s (a slow lockstep sim).
FAULT_WATCH_SIM, FAULT_WATCH_WALL = 0.5, 3.0


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
    carry_extent: float = 0.0                # m of planning margin for the bag
    start: list[float] = field(default_factory=list)
    goal: list[float] = field(default_factory=list)
    planning_time: float | None = None
    plan_duration: float | None = None
    duration: float | None = None            # sim s from segment accepted to stopped
    final_position_error: float | None = None
    final_attitude_error: float | None = None
    tolerance_position: float | None = None
    tolerance_attitude: float | None = None
    rms_position_error: float | None = None
    max_position_error: float | None = None
    max_attitude_error: float | None = None
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
    wall_t1: float | None = None            # to find the leg in the bag (sim time restarts)
    plot: str = ""


class Progress:
    """One progress line: \\r-updated on a tty, a plain line every `period` s otherwise."""

    def __init__(self, stream=None, period: float = 5.0) -> None:
        self.stream = stream or sys.stdout
        self.tty = self.stream.isatty()
        self.period = period
        self._last = 0.0
        self._width = 0

    def update(self, text: str) -> None:
        now = time.monotonic()
        if self.tty:
            if now - self._last < 0.1:
                return
            self.stream.write("\r" + text.ljust(self._width))
            self._width = len(text)
        else:
            if now - self._last < self.period:
                return
            self.stream.write(text + "\n")
        self._last = now
        self.stream.flush()

    def done(self, text: str) -> None:
        if self.tty:
            self.stream.write("\r" + text.ljust(self._width) + "\n")
        else:
            self.stream.write(text + "\n")
        self._width = 0
        self._last = 0.0
        self.stream.flush()


def _vec(v: Any) -> np.ndarray:
    return np.array([v.x, v.y, v.z], dtype=float)


def _quat(q: Any) -> np.ndarray:
    return np.array([q.x, q.y, q.z, q.w], dtype=float)


class MissionClient:
    """The mission's node: subscriptions for state and figures, planner and reset clients."""

    def __init__(self, node: Any, namespace: str = "", stop_flag=None) -> None:
        import roszen
        from roszen import Durability, QoSProfile

        self.roszen = roszen
        self.node = node
        self.log = node.get_logger()
        self.ns = namespace.strip("/")
        pre = f"/{self.ns}/" if self.ns else "/"
        self.stop_flag = stop_flag or (lambda: False)
        latched = QoSProfile(depth=1, durability=Durability.TRANSIENT_LOCAL)
        self.series = sm.Series()
        self.pose: tuple[np.ndarray, np.ndarray] | None = None
        self.sim_time = float("nan")
        self.mob_state: int | None = None
        self.mob_event = ""
        self.mob_changes: list[tuple[float, int, str]] = []
        self.faults: list[str] = []
        self.bag_attached = False
        self.scenario_info: Any = None      # the sim's latched /sim/scenario (ScenarioInfo)
        node.create_subscription("astrobee_msgs/msg/ScenarioInfo", mc.SIM_SCENARIO,
                                 self._on_scenario, latched)
        node.create_subscription("geometry_msgs/msg/PoseStamped", pre + sm.POSE, self._on_pose, 10)
        node.create_subscription("astrobee_msgs/msg/FamCommand", pre + sm.COMMAND,
                                 lambda m: self.series.add_command(m), 10)
        node.create_subscription("astrobee_msgs/msg/ControlState", pre + sm.TRAJ,
                                 lambda m: self.series.add_traj(m), 10)
        node.create_subscription("astrobee_msgs/msg/Contacts", mc.CONTACTS,
                                 lambda m: self.series.add_contacts(m), 10)
        node.create_subscription("astrobee_msgs/msg/BagState", mc.BAG_STATE, self._on_bag, 10)
        # every state change counts: a deep queue (a depth-1 queue keeps only the newest of a
        # burst such as STOPPING -> STOPPED on a loaded machine)
        node.create_subscription("astrobee_msgs/msg/MotionState", pre + sm.MOB_STATE,
                                 self._on_mob, QoSProfile(depth=50, durability=Durability.TRANSIENT_LOCAL))
        node.create_subscription("astrobee_msgs/msg/Fault", "/sim/fault", self._on_fault, 10)
        self.seg_pub = node.create_publisher("astrobee_msgs/msg/Segment", pre + "gnc/ctl/segment",
                                             latched)
        self.planner = node.create_client("astrobee_msgs/srv/PlanGlobal", mc.PLANNER_GLOBAL)
        self.reset_cli = node.create_client("astrobee_msgs/srv/Reset", mc.SIM_RESET)
        self.control_cli = node.create_client("astrobee_msgs/srv/SimControl", mc.SIM_CONTROL)

    # ---- callbacks ----------------------------------------------------------------------
    def _on_pose(self, msg: Any) -> None:
        self.pose = (_vec(msg.pose.position), _quat(msg.pose.orientation))
        self.sim_time = sm._t(msg.header.stamp)
        self.series.add_pose(msg)

    def _on_scenario(self, msg: Any) -> None:
        self.scenario_info = msg

    def _on_bag(self, msg: Any) -> None:
        self.bag_attached = bool(len(msg.attached)) and bool(np.any(np.asarray(msg.attached, bool)))
        self.series.add_bag(msg)

    def _on_mob(self, msg: Any) -> None:
        state = int(msg.state)
        if state != self.mob_state or (msg.fsm_event and msg.fsm_event != self.mob_event):
            self.mob_changes.append((sm._t(msg.header.stamp), state, str(msg.fsm_event)))
        self.mob_state, self.mob_event = state, str(msg.fsm_event)

    def _on_fault(self, msg: Any) -> None:
        if msg.active:
            text = f"{msg.source}: {msg.message} (code {msg.code})"
            self.faults.append(text)
            self.log.warn(f"fault: {text}")

    # ---- waiting ------------------------------------------------------------------------
    def spin_until(self, cond, wall_timeout: float, what: str, tick=None) -> None:
        """Spin callbacks until cond() holds; MissionError after wall_timeout s."""
        deadline = time.monotonic() + wall_timeout
        while not cond():
            if self.stop_flag():
                raise Interrupted()
            if time.monotonic() > deadline:
                raise MissionError(f"timed out after {wall_timeout:.0f} s waiting for {what}")
            self.node.spin_once(timeout_sec=0.05)
            if tick:
                tick()

    def call(self, client: Any, req: Any, timeout: float, what: str) -> Any:
        if not client.wait_for_service(timeout_sec=timeout):
            raise MissionError(f"service {what} not available after {timeout:.0f} s")
        fut = client.call_async(req)
        self.spin_until(fut.done, timeout, f"the answer of {what}")
        return fut.result()

    # ---- one leg ------------------------------------------------------------------------
    def fly(self, scenario_name: str, reset: bool, progress: Progress,
            wall_timeout: float = 600.0, ready_timeout: float = 60.0) -> LegResult:
        """Fly one scenario to its goal; the result says how it went (never raises MissionError)."""
        res = LegResult(scenario=scenario_name)
        wall0 = time.monotonic()
        try:
            self._fly(scenario_name, reset, progress, res, wall_timeout, ready_timeout)
        except MissionError as exc:
            res.success, res.reason = False, str(exc)
        except Interrupted:
            res.success, res.reason = False, "interrupted (SIGINT/SIGTERM)"
            self.interrupted_result = res
            raise
        finally:
            res.wall_time = time.monotonic() - wall0
            if res.wall_t0 is not None and res.wall_t1 is None:
                res.wall_t1 = time.time()
            self._finish(res)
        return res

    def _fly(self, name: str, reset: bool, progress: Progress, res: LegResult,
             wall_timeout: float, ready_timeout: float) -> None:
        if not reset and (self.scenario_info is None or self.scenario_info.name != name):
            self.spin_until(lambda: self.scenario_info is not None, ready_timeout,
                            "the simulator's scenario (/sim/scenario)")
            if self.scenario_info.name != name:
                reset = True      # the sim runs another scenario: bring it to this one
        if reset:
            # pause first so that no command of the previous leg (stamped with its late sim
            # times) is still in flight when the clock restarts, then reset and resume
            ctl = self.roszen.request_class("astrobee_msgs/srv/SimControl")
            pause, resume = ctl(), ctl()
            pause.command, resume.command = mc.SimControl.PAUSE, mc.SimControl.RESUME
            self.call(self.control_cli, pause, ready_timeout, "/sim/control (pause)")
            end = time.monotonic() + 0.3
            self.spin_until(lambda: time.monotonic() > end, 5.0, "in-flight commands")
            req = self.roszen.request_class("astrobee_msgs/srv/Reset")()
            req.scenario, req.seed = name, 0
            resp = self.call(self.reset_cli, req, ready_timeout, "/sim/reset")
            self.call(self.control_cli, resume, ready_timeout, "/sim/control (resume)")
            if not resp.success:
                raise MissionError(f"/sim/reset to {name} failed: {resp.message}")
            self.pose = None
            # let the controller see the jump and hold the new pose before a segment comes
            n_changes, n_poses = len(self.mob_changes), len(self.series.pose_t)
            self.spin_until(lambda: len(self.mob_changes) > n_changes
                            or len(self.series.pose_t) > n_poses + 60, ready_timeout,
                            "the controller to take the reset")
        # the scenario as the simulator built it (launch overrides included)
        self.spin_until(lambda: self.scenario_info is not None and self.scenario_info.name == name,
                        ready_timeout, f"the simulator's description of {name} (/sim/scenario)")
        info = self.scenario_info
        fm = flight_modes.get(info.flight_mode or None)
        res.flight_mode = fm.name
        res.tolerance_position, res.tolerance_attitude = fm.tolerance_pos, fm.tolerance_att
        res.carrying_bag = bool(info.carrying_bag)
        if not info.has_goal:
            raise MissionError(f"scenario {name} has no goal")
        goal_p, goal_q = mc.pose(info.goal)
        goal_q = rot.normalize(goal_q)
        res.goal = [*goal_p.tolist(), *goal_q.tolist()]
        if self.ns not in list(info.robots):
            raise MissionError(f"scenario {name} has no robot {self.ns or '(default)'!r}: "
                               f"robots {list(info.robots)}")
        start_p, _ = mc.pose(info.starts[list(info.robots).index(self.ns)])
        progress.update(f"[mission] {name}: waiting for the robot's state and the controller")
        self.spin_until(lambda: self.pose is not None
                        and float(np.linalg.norm(self.pose[0] - start_p)) < 0.5
                        and self.mob_state in (IDLE, STOPPED), ready_timeout,
                        f"the robot at the start of {name} and the controller ready")
        pos, q = self.pose
        res.start = [*pos.tolist(), *q.tolist()]

        req = self.roszen.request_class("astrobee_msgs/srv/PlanGlobal")()
        _set_pose(req.start, pos, q)
        _set_pose(req.goal, goal_p, goal_q)
        req.flight_mode = fm.name
        req.face_forward = bool(info.face_forward)
        # the bag trails along the path: the scenario's margin (bags.yaml's carry_extent default)
        req.carry_extent = float(info.carry_extent) if info.carrying_bag else 0.0
        res.carry_extent = req.carry_extent
        progress.update(f"[mission] {name}: planning")
        plan = self.call(self.planner, req, 120.0, "/mob/planner/global")
        res.planning_time = float(plan.planning_time)
        if not plan.success:
            raise MissionError(f"planning failed (code {plan.code}): {plan.message}")
        res.plan_duration = float(plan.duration)
        self.log.info(f"{name}: plan of {plan.duration:.1f} s in {plan.planning_time:.2f} s, "
                      f"{len(plan.segment)} states")

        seg = self.roszen.message_class("astrobee_msgs/msg/Segment")()
        now = self.node.get_clock().now()
        seg.header.stamp = now.to_msg()
        seg.header.frame_id = "world"
        seg.flight_mode = fm.name
        seg.segment = list(plan.segment)
        n_changes = len(self.mob_changes)
        self.series = sm.Series()  # this leg's figures (the subscriptions feed self.series)
        self.faults = []  # faults during this leg's flight only
        t_sent = self.sim_time
        res.sim_t0 = t_sent
        wall_sent = time.monotonic()
        res.wall_t0 = time.time()
        self.seg_pub.publish(seg)

        def controlling_seen() -> bool:
            return any(s == CONTROLLING for _, s, _ in self.mob_changes[n_changes:])

        fault_seen: dict[str, float] = {}

        def faulted() -> bool:
            """A fault arrived during the flight and the robot was watched for a while since."""
            if not self.faults:
                return False
            if not fault_seen:
                fault_seen.update(sim=self.sim_time, wall=time.monotonic())
            return (self.sim_time - fault_seen["sim"] >= FAULT_WATCH_SIM
                    or time.monotonic() - fault_seen["wall"] >= FAULT_WATCH_WALL)

        def finished() -> bool:
            if faulted():
                return True
            seen = False
            for _, s, _ in self.mob_changes[n_changes:]:
                seen = seen or s == CONTROLLING
                if seen and s in (STOPPED, IDLE):
                    return True
            return False

        def tick() -> None:
            e = self.series.pos_error[-1] if self.series.pos_error else float("nan")
            c = self.series.robot_clearance[-1] if self.series.robot_clearance else float("nan")
            el = self.sim_time - t_sent
            wall = time.monotonic() - wall_sent
            rtf = el / wall if wall > 0 else float("nan")
            progress.update(f"[mission] {name}: {NAMES.get(self.mob_state, self.mob_state)} "
                            f"t={el:5.1f}/{plan.duration:.1f} s  err {e:.3f} m  "
                            f"clear {c:.2f} m  {rtf:4.1f}x real time")

        # A controller that dies before its CONTROLLING state reaches us (its latched state
        # dies with it) shows up as the sim's watchdog fault: stop waiting then, too.
        self.spin_until(lambda: controlling_seen() or faulted(), 30.0,
                        "the controller to accept the segment", tick)
        self.spin_until(finished, wall_timeout, "the end of the flight", tick)
        if fault_seen:
            res.sim_t1, res.wall_t1 = self.sim_time, time.time()
            res.sim_time = self.sim_time - t_sent
            if self.pose is not None:
                res.final_position_error = float(np.linalg.norm(self.pose[0] - goal_p))
                res.final_attitude_error = rot.angle_between(self.pose[1], goal_q)
            raise MissionError(f"flight aborted on a fault: {self.faults[0]}")
        t_end = next(t for t, s, _ in self.mob_changes[n_changes:] if s in (STOPPED, IDLE)
                     and any(s2 == CONTROLLING for _, s2, _ in self.mob_changes[n_changes:]))
        res.sim_t1 = self.sim_time
        res.wall_t1 = time.time()
        t_acc = next(t for t, s, _ in self.mob_changes[n_changes:] if s == CONTROLLING)
        res.duration = t_end - t_acc
        wall = time.monotonic() - wall_sent
        res.sim_time = self.sim_time - t_sent
        res.real_time_factor = res.sim_time / wall if wall > 0 else None
        pos, q = self.pose
        res.final_position_error = float(np.linalg.norm(pos - goal_p))
        res.final_attitude_error = rot.angle_between(q, goal_q)

    def _finish(self, res: LegResult) -> None:
        s = self.series
        res.faults = list(self.faults)
        for k, v in s.tracking().items():
            setattr(res, k, v if v == v else None)
        cl = s.clearance()
        res.min_robot_clearance, res.min_bag_clearance = cl["min_robot_clearance"], cl["min_bag_clearance"]
        res.contacts = cl["contact_samples"]
        res.contact_bodies = sorted(s.contact_bodies)
        if res.reason == "":
            problems = []
            if res.final_position_error is None or res.final_position_error > res.tolerance_position:
                problems.append(f"final position error {res.final_position_error:.3f} m > "
                                f"{res.tolerance_position} m")
            if res.final_attitude_error is None or res.final_attitude_error > res.tolerance_attitude:
                problems.append(f"final attitude error {res.final_attitude_error:.3f} rad > "
                                f"{res.tolerance_attitude} rad")
            if res.contacts:
                problems.append(f"{res.contacts} contact samples ({', '.join(res.contact_bodies)})")
            if res.faults:
                problems.append(f"faults: {'; '.join(res.faults)}")
            res.success = not problems
            res.reason = "goal reached" if not problems else "; ".join(problems)


def _set_pose(dst: Any, p: np.ndarray, q: np.ndarray) -> None:
    dst.position.x, dst.position.y, dst.position.z = (float(v) for v in p)
    dst.orientation.x, dst.orientation.y, dst.orientation.z, dst.orientation.w = (float(v) for v in q)


def write_outputs(run_dir: Path, legs: list[LegResult], series: list[sm.Series],
                  status: str) -> dict[str, Any]:
    """summary.json and one plot per leg in run_dir."""
    run_dir.mkdir(parents=True, exist_ok=True)
    boxes = config.keep_in_boxes()
    for leg, s in zip(legs, series):
        if s.position:
            name = "plot.png" if len(legs) == 1 else f"plot_{leg.scenario}.png"
            try:
                sm.plot(s, run_dir / name, boxes, title=f"{leg.scenario}: {leg.reason}",
                        start=leg.start[:3] or None, goal=leg.goal[:3] or None)
                leg.plot = name
            except Exception as exc:  # noqa: BLE001 - a plot failure must not lose the summary
                leg.plot = f"plot failed: {exc}"
    data = {"success": bool(legs) and all(l.success for l in legs), "status": status,
            "legs": [asdict(l) for l in legs]}
    if len(legs) == 1:
        data.update({k: v for k, v in asdict(legs[0]).items() if k not in data})
    sm.write_json(run_dir / "summary.json", data)
    return data


def run_mission(scenarios: list[str], run_dir: Path, namespace: str = "",
                argv: list[str] | None = None, wall_timeout: float = 600.0,
                ready_timeout: float = 90.0, stream=None) -> int:
    """Fly the scenarios in order in the running graph; write run_dir/summary.json + plots.
    Returns the process exit status (0 all legs succeeded, 1 failure, 130 interrupted)."""
    import roszen

    stop = {"flag": False}

    def handler(signum, frame):  # noqa: ARG001
        stop["flag"] = True

    old = {}
    if signal.getsignal(signal.SIGINT) is not None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                old[sig] = signal.signal(sig, handler)
            except ValueError:  # not the main thread
                pass
    for name in scenarios:
        Scenario.load(name)  # fail early on an unknown or invalid scenario
    args = list(argv or ["mission"])
    if "--ros-args" not in args:
        args += ["--ros-args"]
    args += ["-p", "use_sim_time:=true"]
    node = roszen.Node("mission", namespace="", argv=args)
    client = MissionClient(node, namespace, stop_flag=lambda: stop["flag"])
    progress = Progress(stream)
    legs: list[LegResult] = []
    all_series: list[sm.Series] = []
    status = "completed"
    code = 0
    try:
        for i, name in enumerate(scenarios):
            try:
                res = client.fly(name, reset=i > 0, progress=progress, wall_timeout=wall_timeout,
                                 ready_timeout=ready_timeout)
            except Interrupted:
                legs.append(getattr(client, "interrupted_result", None) or client_last(client, name))
                all_series.append(client.series)
                status, code = "interrupted", 130
                break
            legs.append(res)
            all_series.append(client.series)
            client.series = sm.Series()  # samples after this leg's end belong to no leg
            progress.done(f"[mission] {name}: {'SUCCESS' if res.success else 'FAILED'}: {res.reason}"
                          + (f" ({res.duration:.1f} s sim, {res.real_time_factor:.1f}x real time)"
                             if res.duration is not None and res.real_time_factor else ""))
            if not res.success:
                code = 1
                status = "failed"
                break
    finally:
        data = write_outputs(Path(run_dir), legs, all_series, status)
        try:
            node.destroy_node()
        except Exception:  # noqa: BLE001
            pass
        for sig, h in old.items():
            signal.signal(sig, h)
    print(f"[mission] summary: {Path(run_dir) / 'summary.json'} "
          f"({'success' if data['success'] else status})", file=stream or sys.stdout, flush=True)
    return code


def client_last(client: MissionClient, name: str) -> LegResult:
    res = LegResult(scenario=name, reason="interrupted (SIGINT/SIGTERM)")
    client._finish(res)
    res.success = False
    return res


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    own, _, ros = (argv[:argv.index("--ros-args")], None, argv[argv.index("--ros-args"):]) \
        if "--ros-args" in argv else (argv, None, [])
    p = argparse.ArgumentParser(prog="astrobee mission", description=__doc__.split("\n")[0])
    p.add_argument("--scenario", action="append", required=True,
                   help="scenario to fly (repeat for several legs)")
    p.add_argument("--run-dir", default=None, help="output directory (default runs/<time>)")
    p.add_argument("--namespace", default="", help="robot namespace")
    p.add_argument("--timeout", type=float, default=600.0, help="wall seconds per leg")
    a = p.parse_args(own)
    try:
        for name in a.scenario:
            Scenario.load(name)
    except (ScenarioError, config.ConfigError) as exc:
        print(f"astrobee mission: {exc}", file=sys.stderr)
        return 2
    run_dir = Path(a.run_dir) if a.run_dir else Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    return run_mission(a.scenario, run_dir, a.namespace, ["mission", *ros], wall_timeout=a.timeout)


if __name__ == "__main__":
    sys.exit(main())
