"""The mission client: plan a scenario's route, hand it to the controller(s), follow it to the
end and write the run's summary.json and plot.

One robot: a global plan (/mob/planner/global). Two robots (a scenario whose /sim/scenario lists
two, holding the cargo bag's two handles): a formation plan (/mob/planner/formation), one
segment per robot on `<ns>/gnc/ctl/segment`, all with the same start stamp; the leg ends when
every robot is done, or on a fault of any robot (named in the reason). Per-robot figures and
the verdict (summary.leg_verdict) go into summary.json's legs[i].robots.

    python -m astrobee_bringup.mission --scenario node2_to_jem --run-dir runs/X [--scenario node2_to_jem_bag]

With several scenarios (the demo) the legs fly one after the other in the same graph, the
simulation reset to each leg's scenario (/sim/reset) before it. Exit status: 0 when every leg
succeeded, 1 when one failed, 2 for a bad argument, 130 when interrupted (SIGINT/SIGTERM).
The launch description runs it as one of its processes (see astrobee_bringup/launch/cargo_transport.py).

Deterministic lockstep (`--handover`, with sim_node's start_paused: the launch sets both in
lockstep): every leg starts from a paused sim. The mission waits until the graph is ready (each
robot's controller up, a recorder (`--await-recorder`) subscribed to every topic of the sim),
resets the sim (the state of t=0 published once, to every node), plans from that state, hands
the segments over stamped to start at t=0 + HANDOVER_LEAD and resumes the sim once every
controller holds its segment; the sim then runs in chunks (/sim/control RESUME with steps) and
the leg ends at the first chunk end after every robot stopped. Nothing depends on the wall
clock: the same seed gives the same recording (tests/e2e/test_determinism_launch.py).

Lost peers: the simulator, the planner or a flying robot's controller leaving the graph (even
kill -9) fails the leg at once with "lost node <name>" (astrobee_bringup.peers).
"""
from __future__ import annotations

import argparse
import math
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
from astrobee_bringup.peers import PeerLost, PeerWatch, relay_missing

IDLE, STOPPED, STOPPING, CONTROLLING = (mc.MotionState.IDLE, mc.MotionState.STOPPED,
                                        mc.MotionState.STOPPING, mc.MotionState.CONTROLLING)
NAMES = mc.MotionState.NAMES
PEERS = ("sim_node", "planner_node")     # nodes every leg needs (plus its controllers)
MAX_RESUME_STEPS = 100_000              # sim_node's bound on one /sim/control request


# After a fault (the sim's propulsion watchdog: the controller is gone) the leg ends once the
# robot has been watched coasting this long (sim s), or this many wall s (a slow lockstep sim).
FAULT_WATCH_SIM, FAULT_WATCH_WALL = 0.5, 3.0
# Formation segments start this far (sim s) after the request: every controller has its
# segment before the common start stamp, so the robots start together.
FORMATION_LEAD = 0.5
# Deterministic runs: the segments start this long (sim s) after the reset's t=0 (the sim is
# paused until every controller holds its segment; the lead lets each controller hold the start
# with the cargo bag observed and a freshly built bag settle a moment, as a mission planning
# in a running sim had), and the sim runs in chunks of CHUNK_STEPS physics steps (1 s at the
# default 350 Hz) once the plan is flown.
HANDOVER_LEAD = 1.0
CHUNK_STEPS = 350


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
    wall_t1: float | None = None            # to find the leg in the recording (sim time restarts)
    robots: list[dict[str, Any]] = field(default_factory=list)   # summary.RobotResult per robot
    plot: str = ""
    realism: dict[str, Any] = field(default_factory=dict)      # knobs on (sim's /sim/realism)
    disturbances: list[dict[str, Any]] = field(default_factory=list)   # pulses applied


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


class RobotWatch:
    """What the mission follows of one robot (namespace `name`, "" = the default robot): its
    pose, reference and commands (a Series), its /mob/state changes and its /sim/fault."""

    def __init__(self, node: Any, name: str, latched: Any, deep_latched: Any) -> None:
        pre = mc.ns(name) + "/"
        self.name = name
        self.label = sm.robot_label(name)
        self.named = sm.robot_named(name)
        self.series = sm.Series()
        self.pose: tuple[np.ndarray, np.ndarray] | None = None
        self.sim_time = float("nan")
        self.mob_state: int | None = None
        self.mob_event = ""
        self.mob_changes: list[tuple[float, int, str]] = []
        self.faults: list[tuple[float, str]] = []       # (sim time, text) during this flight
        self.fault_active: tuple[float, str] | None = None
        self.log = node.get_logger()
        node.create_subscription("geometry_msgs/msg/PoseStamped", pre + sm.POSE, self._on_pose, 10)
        self.cmd_ns = -1                # stamp (ns) of the last command (any control mode)
        node.create_subscription("astrobee_msgs/msg/FamCommand", pre + sm.COMMAND,
                                 self._on_command, 10)
        node.create_subscription("astrobee_msgs/msg/ControlState", pre + sm.TRAJ,
                                 lambda m: self.series.add_traj(m), 10)
        # every state change counts: a deep queue (a depth-1 queue keeps only the newest of a
        # burst such as STOPPING -> STOPPED on a loaded machine)
        node.create_subscription("astrobee_msgs/msg/MotionState", pre + sm.MOB_STATE,
                                 self._on_mob, deep_latched)
        node.create_subscription("astrobee_msgs/msg/Fault", pre + mc.FAULT, self._on_fault,
                                 deep_latched)
        self.seg_pub = node.create_publisher("astrobee_msgs/msg/Segment", pre + mc.SEGMENT, latched)

    def _on_command(self, msg: Any) -> None:
        self.cmd_ns = mc.stamp_ns(msg.header.stamp)
        self.series.add_command(msg)

    def _on_pose(self, msg: Any) -> None:
        self.pose = (_vec(msg.pose.position), _quat(msg.pose.orientation))
        self.sim_time = sm._t(msg.header.stamp)
        self.series.add_pose(msg)

    def _on_mob(self, msg: Any) -> None:
        state = int(msg.state)
        if state != self.mob_state or (msg.fsm_event and msg.fsm_event != self.mob_event):
            self.mob_changes.append((sm._t(msg.header.stamp), state, str(msg.fsm_event)))
        self.mob_state, self.mob_event = state, str(msg.fsm_event)

    def _on_fault(self, msg: Any) -> None:
        if msg.active:
            fault = (sm._t(msg.header.stamp), f"{msg.source}: {msg.message} (code {msg.code})")
            self.fault_active = fault
            self.faults.append(fault)
            self.log.warn(f"fault of {self.named}: {fault[1]}")
        else:
            self.fault_active = None

    def start_leg(self) -> int:
        """Forget the previous leg's figures and faults (an active fault stays); returns the
        index of the next /mob/state change."""
        self.series = sm.Series()
        self.faults = [self.fault_active] if self.fault_active else []
        return len(self.mob_changes)

    def controlling_since(self, n: int) -> bool:
        return any(s == CONTROLLING for _, s, _ in self.mob_changes[n:])

    def done_since(self, n: int) -> float | None:
        """Sim time the robot stopped after controlling (changes from index n), else None."""
        seen = False
        for t, s, _ in self.mob_changes[n:]:
            seen = seen or s == CONTROLLING
            if seen and s in (STOPPED, IDLE):
                return t
        return None

    def position_at(self, t: float) -> list[float] | None:
        """The recorded position nearest sim time t."""
        if not self.series.pose_t:
            return None
        i = int(np.argmin(np.abs(np.asarray(self.series.pose_t) - t)))
        return list(self.series.position[i])


class MissionClient:
    """The mission's node: per-robot watches, the cargo bag and contacts, planner and reset
    clients."""

    def __init__(self, node: Any, namespace: str = "", stop_flag=None, handover: bool = False,
                 await_recorder: bool = False) -> None:
        import roszen
        from roszen import Durability, QoSProfile

        self.roszen = roszen
        self.node = node
        self.log = node.get_logger()
        self.ns = namespace.strip("/")
        self.stop_flag = stop_flag or (lambda: False)
        self.handover = handover                # deterministic lockstep (see the module doc)
        self.await_recorder = await_recorder
        # the simulator or planner (and, once a leg flies, its controllers) leaving the graph
        # (killed, even -9) ends the wait at once, named
        self.peers = PeerWatch(node, nodes=PEERS)
        self.scenario_count = 0             # /sim/scenario messages received (one per reset)
        self.sim_robots: set[str] = set()   # every robot the sim has built (has topics for)
        self.latched = QoSProfile(depth=1, durability=Durability.TRANSIENT_LOCAL)
        self.deep_latched = QoSProfile(depth=50, durability=Durability.TRANSIENT_LOCAL)
        self.watches: dict[str, RobotWatch] = {}
        self._goals: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._starts: dict[str, list[float]] = {}
        self.flying: list[str] = [self.ns]          # the robots of the current leg
        self.bag_state: Any = None
        self.scenario_info: Any = None      # the sim's latched /sim/scenario (ScenarioInfo)
        node.create_subscription("astrobee_msgs/msg/ScenarioInfo", mc.SIM_SCENARIO,
                                 self._on_scenario, self.latched)
        node.create_subscription("astrobee_msgs/msg/Contacts", mc.CONTACTS, self._on_contacts, 10)
        self.realism: dict = {}
        node.create_subscription("std_msgs/msg/String", "/sim/realism", self._on_realism, self.latched)
        node.create_subscription("astrobee_msgs/msg/BagState", mc.BAG_STATE, self._on_bag, 10)
        self.watch(self.ns)
        self.planner = node.create_client("astrobee_msgs/srv/PlanGlobal", mc.PLANNER_GLOBAL)
        self.formation = node.create_client("astrobee_msgs/srv/PlanFormation", mc.PLANNER_FORMATION)
        self.reset_cli = node.create_client("astrobee_msgs/srv/Reset", mc.SIM_RESET)
        self.control_cli = node.create_client("astrobee_msgs/srv/SimControl", mc.SIM_CONTROL)

    def watch(self, name: str) -> RobotWatch:
        if name not in self.watches:
            self.watches[name] = RobotWatch(self.node, name, self.latched, self.deep_latched)
        return self.watches[name]

    @property
    def series(self) -> sm.Series:
        """The first robot's series of the current leg (with the contacts and cargo bag)."""
        return self.watches[self.flying[0]].series

    def leg_series(self) -> dict[str, sm.Series]:
        return {n: self.watches[n].series for n in self.flying}

    @property
    def sim_time(self) -> float:
        return max((self.watches[n].sim_time for n in self.flying
                    if self.watches[n].sim_time == self.watches[n].sim_time), default=float("nan"))

    # ---- callbacks ----------------------------------------------------------------------
    def _on_scenario(self, msg: Any) -> None:
        self.scenario_info = msg
        self.scenario_count += 1
        self.sim_robots.update(str(r) for r in msg.robots)

    def _on_realism(self, msg: Any) -> None:
        """/sim/realism (YAML: knobs, schedule, applied), recorded with each leg."""
        import yaml
        try:
            data = yaml.safe_load(msg.data)
            self.realism = data if isinstance(data, dict) else {}
        except yaml.YAMLError:
            self.log.warn("malformed /sim/realism dropped")

    def _on_contacts(self, msg: Any) -> None:
        for n in self.flying:
            self.watches[n].series.add_contacts(msg)

    def _on_bag(self, msg: Any) -> None:
        self.bag_state = msg
        for n in self.flying:
            self.watches[n].series.add_bag(msg)

    # ---- waiting ------------------------------------------------------------------------
    def spin_until(self, cond, wall_timeout: float, what, tick=None) -> None:
        """Spin callbacks until cond() holds; MissionError after wall_timeout s (`what`: text,
        or a function giving it at the time-out)."""
        deadline = time.monotonic() + wall_timeout
        while not cond():
            if self.stop_flag():
                raise Interrupted()
            if time.monotonic() > deadline:
                raise MissionError(f"timed out after {wall_timeout:.0f} s waiting for "
                                   f"{what() if callable(what) else what}")
            self._check_peers()
            self.node.spin_once(timeout_sec=0.05)
            if tick:
                tick()

    def _check_peers(self) -> None:
        """MissionError("lost node sim_node") once a required node has left the graph; a
        Ctrl-C that stops the whole launch (the sim with it) stays an interruption."""
        try:
            self.peers.check()
        except PeerLost as exc:
            end = time.monotonic() + 0.5
            while time.monotonic() < end:
                if self.stop_flag():
                    raise Interrupted() from None
                time.sleep(0.05)
            lost = str(exc)
            if "sim_node" not in lost:      # the sim's watchdog stops a robot left uncommanded:
                why = self._watch_coasting()  # recorded and named, as any fault
                if why:
                    raise MissionError(f"{lost}; {why}") from None
            raise MissionError(lost) from None

    def _watch_coasting(self) -> str:
        """After a lost peer: follow the flying robots until a fault of one has been watched
        for FAULT_WATCH_SIM sim s (FAULT_WATCH_WALL wall s at most, from now); the fault's cause
        ("flight aborted on a fault ..."), "" when none came."""
        ws = [self.watches[n] for n in self.flying]
        end = time.monotonic() + FAULT_WATCH_WALL
        seen_at = None
        while time.monotonic() < end:
            if self.stop_flag():
                raise Interrupted()
            faulty = [w for w in ws if w.fault_active]
            if faulty and seen_at is None:
                seen_at = self.sim_time
            if seen_at is not None and self.sim_time - seen_at >= FAULT_WATCH_SIM:
                break
            self.node.spin_once(timeout_sec=0.05)
        first = next((w for w in ws if w.fault_active), None)
        if first is None:
            return ""
        return (f"flight aborted on a fault of {first.named}: {first.fault_active[1]}"
                if len(ws) > 1 else f"flight aborted on a fault: {first.fault_active[1]}")

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
        self._goals: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._starts: dict[str, list[float]] = {}
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

    def _reset(self, name: str, ready_timeout: float) -> None:
        # pause first so that no command of the previous leg (stamped with its late sim
        # times) is still in flight when the clock restarts, then reset and resume
        ctl = self.roszen.request_class("astrobee_msgs/srv/SimControl")
        pause, resume = ctl(), ctl()
        pause.command, resume.command = mc.SimControl.PAUSE, mc.SimControl.RESUME
        self.call(self.control_cli, pause, ready_timeout, "/sim/control (pause)")
        end = time.monotonic() + 0.3
        self.spin_until(lambda: time.monotonic() > end, 5.0, "in-flight commands")
        req = self.roszen.request_class("astrobee_msgs/srv/Reset")()
        req.scenario, req.seed = name, self._seed()
        resp = self.call(self.reset_cli, req, ready_timeout, "/sim/reset")
        self.call(self.control_cli, resume, ready_timeout, "/sim/control (resume)")
        if not resp.success:
            raise MissionError(f"/sim/reset to {name} failed: {resp.message}")
        # let the controllers see the jump and hold the new pose before a segment comes
        ws = [self.watches[n] for n in self.flying]
        for w in ws:
            w.pose = None
        marks = [(len(w.mob_changes), len(w.series.pose_t)) for w in ws]
        self.spin_until(lambda: all(len(w.mob_changes) > c or len(w.series.pose_t) > p + 60
                                    for w, (c, p) in zip(ws, marks)), ready_timeout,
                        "the controller to take the reset")

    def _seed(self) -> int:
        """The seed the sim runs with (the launch's): legs after a reset keep it."""
        return int(self.scenario_info.seed) if self.scenario_info is not None else 0

    def _control(self, command: int, steps: int, timeout: float, what: str) -> Any:
        req = self.roszen.request_class("astrobee_msgs/srv/SimControl")()
        req.command, req.steps = command, steps
        resp = self.call(self.control_cli, req, timeout, f"/sim/control ({what})")
        if not resp.success:
            raise MissionError(f"/sim/control ({what}) refused: {resp.message}")
        return resp

    def _graph_not_ready(self, robots: list[str]) -> str:
        """Why the graph cannot take a deterministic leg yet ("" when it can): each robot's
        controller up (its latched /mob/state) with a publisher of its command topic (with a
        safety filter, safety:=node: a node publishing it that subscribes the controller's
        `<cmd>_nominal`), a recorder on every topic of the sim."""
        n = self.node
        for r in robots:
            w = self.watch(r)
            cmd = mc.robot_topic(r, sm.COMMAND)
            if w.mob_state is None:
                return f"{w.named}: no controller ({mc.robot_topic(r, sm.MOB_STATE)})"
            if n.count_publishers(cmd) == 0:
                return f"{w.named}: no publisher of {cmd}"
            why = relay_missing(n, cmd + "_nominal", cmd)
            if why:
                return f"{w.named}: {why}"
        if self.await_recorder:
            for topic, _ in n.get_topic_names_and_types():
                if any(p.startswith("_") for p in topic.split("/") if p):
                    continue
                if not any(e.node_name == "sim_node" for e in n.get_publishers_info_by_topic(topic)):
                    continue
                if not any("rosbag2_recorder" in e.node_name
                           for e in n.get_subscriptions_info_by_topic(topic)):
                    return f"no recorder subscribed to {topic}"
        return ""

    def _paused_reset(self, name: str, ready_timeout: float) -> None:
        """Deterministic lockstep: with the sim paused and the graph ready, reset to `name`
        (the state of t=0 published once, to every node) and wait until every controller has
        answered it. A reset that built topics no recorder had yet (a robot new to this leg) is
        repeated once the recorder has them."""
        self.spin_until(lambda: self.scenario_info is not None, ready_timeout,
                        "the simulator's scenario (/sim/scenario)")
        self._control(mc.SimControl.PAUSE, 0, ready_timeout, "pause")
        end = time.monotonic() + 0.3     # commands answering the last tick still on their way
        self.spin_until(lambda: time.monotonic() > end, 5.0, "in-flight commands")
        info = self.scenario_info
        robots = list(info.robots) if info.name == name else \
            list(Scenario.load(name).robot_names)
        seed = self._seed()
        for attempt in range(2):
            self.spin_until(lambda: not self._graph_not_ready(robots), ready_timeout,
                            lambda: f"the graph ready for {name} ({self._graph_not_ready(robots)})")
            known, had = set(self.watches), set(self.sim_robots)
            for w in self.watches.values():     # what comes now answers this reset
                w.pose, w.cmd_ns = None, -1
            count = self.scenario_count
            req = self.roszen.request_class("astrobee_msgs/srv/Reset")()
            req.scenario, req.seed = name, seed
            resp = self.call(self.reset_cli, req, ready_timeout, "/sim/reset")
            if not resp.success:
                raise MissionError(f"/sim/reset to {name} failed: {resp.message}")
            self.spin_until(lambda: self.scenario_count > count, ready_timeout,
                            f"the simulator's description of {name} after its reset")
            built = list(self.scenario_info.robots)
            ws = [self.watches[r] for r in built if r in known]

            def late() -> str:
                return ", ".join(w.named for w in ws
                                 if w.pose is None or w.cmd_ns != mc.to_ns(w.sim_time))
            # every controller has answered the state of t=0 before its segment comes
            self.spin_until(lambda: not late(), ready_timeout,
                            lambda: f"the state of t=0 answered by every controller ({late()} did not)")
            # a robot the sim never had: its topics are new, no recorder had them at the reset
            # (decided by the scenario, not by how fast the recorder subscribes)
            if attempt or (len(ws) == len(built) and set(built) <= had):
                break
            robots = built

    def _run_chunks(self, ws: list[RobotWatch], marks: dict[str, int], duration: float,
                    wall_timeout: float, tick) -> None:
        """Deterministic lockstep: resume for the plan's duration, then a chunk at a time, until
        a chunk ends with every robot stopped (or a fault) before its last tick. The sim pauses
        at each chunk's end; that the robots stopped is read once every controller has answered
        the last tick, so the leg ends at a tick the flight fixes, whatever the wall clock."""
        deadline = time.monotonic() + wall_timeout
        first = HANDOVER_LEAD + duration + 1.0      # the lead, the plan and a settling second
        steps = min(int(math.ceil(first * CHUNK_STEPS)), MAX_RESUME_STEPS)
        while True:
            resp = self._control(mc.SimControl.RESUME, steps, 30.0, "resume")
            t_end = mc.stamp_ns(resp.sim_time)
            # the last tick's answers and its pose: under load the pose of t_end can come after
            # the controllers' answers to it (another publisher, another path through the router)
            self.spin_until(lambda: all(w.cmd_ns >= t_end and w.sim_time == w.sim_time
                                        and mc.to_ns(w.sim_time) >= t_end for w in ws),
                            max(1.0, deadline - time.monotonic()), "the end of the flight", tick)
            # everything received before the last tick's answers (the states and faults of
            # earlier ticks) runs now: the executor serves topics in turn, not in the order
            # they came
            while self.node.spin_once(timeout_sec=0):
                pass
            t = t_end * 1e-9
            done = [w.done_since(marks[w.name]) for w in ws]
            if (all(d is not None and d < t - 1e-9 for d in done)
                    or any(f < t - 1e-9 for w in ws for f, _ in w.faults)):
                return
            steps = CHUNK_STEPS

    def _fly(self, name: str, reset: bool, progress: Progress, res: LegResult,
             wall_timeout: float, ready_timeout: float) -> None:
        if self.handover:
            progress.update(f"[mission] {name}: waiting for the graph, then the sim's reset")
            self._paused_reset(name, ready_timeout)
            reset = False
        if not reset and (self.scenario_info is None or self.scenario_info.name != name):
            self.spin_until(lambda: self.scenario_info is not None, ready_timeout,
                            "the simulator's scenario (/sim/scenario)")
            if self.scenario_info.name != name:
                reset = True      # the sim runs another scenario: bring it to this one
        if reset:
            self._reset(name, ready_timeout)
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
        names = list(info.robots)
        if len(names) == 1 and self.ns and names != [self.ns]:
            raise MissionError(f"scenario {name} has no robot {self.ns!r}: robots {names}")
        if not names or len(names) > 2:
            raise MissionError(f"scenario {name} has {len(names)} robots: the mission flies one "
                               f"robot, or two carrying a cargo bag in formation")
        self.flying = names
        ws = [self.watch(n) for n in names]
        starts = {n: mc.pose(info.starts[i])[0] for i, n in enumerate(names)}
        self._goals = {names[0]: (goal_p, goal_q)}

        def not_ready() -> str:
            late = [w for w in ws if not (w.pose is not None and
                                          float(np.linalg.norm(w.pose[0] - starts[w.name])) < 0.5
                                          and w.mob_state in (IDLE, STOPPED))]
            return ("; ".join(f"{w.named}: " + ("no pose" if w.pose is None else
                              "not at its start" if np.linalg.norm(w.pose[0] - starts[w.name]) >= 0.5
                              else f"no controller ready ({mc.robot_topic(w.name, sm.MOB_STATE)}: "
                                   f"{NAMES.get(w.mob_state, w.mob_state)})") for w in late)
                    if late else "")

        progress.update(f"[mission] {name}: waiting for the robots' states and controllers"
                        if len(ws) > 1 else f"[mission] {name}: waiting for the robot's state and the controller")
        self.spin_until(lambda: not not_ready(), ready_timeout,
                        lambda: f"the robots at the start of {name} and their controllers ready "
                                f"({not_ready()})")
        self._watch_peers(ws)
        for w in ws:
            pos, q = w.pose
            self._starts[w.name] = [*pos.tolist(), *q.tolist()]
        res.start = self._starts[names[0]]
        progress.update(f"[mission] {name}: planning")
        if len(names) == 1:
            segments, duration = self._plan_one(ws[0], info, fm, goal_p, goal_q, res)
        else:
            segments, duration = self._plan_formation(ws, info, fm, goal_p, goal_q, res)
        res.plan_duration = duration

        marks = {w.name: w.start_leg() for w in ws}
        t_sent = self.sim_time
        res.sim_t0 = t_sent
        wall_sent = time.monotonic()
        res.wall_t0 = time.time()
        for w, seg in zip(ws, segments):     # one start stamp for all (formation plans)
            w.seg_pub.publish(seg)
        fault_seen: dict[str, float] = {}

        def faulted() -> bool:
            """A fault arrived during the flight and the robots were watched for a while since."""
            if not any(w.faults for w in ws):
                return False
            if not fault_seen:
                fault_seen.update(sim=self.sim_time, wall=time.monotonic())
            return (self.sim_time - fault_seen["sim"] >= FAULT_WATCH_SIM
                    or time.monotonic() - fault_seen["wall"] >= FAULT_WATCH_WALL)

        def finished() -> bool:
            return faulted() or all(w.done_since(marks[w.name]) is not None for w in ws)

        def tick() -> None:
            errs = "  ".join((f"{w.label} " if len(ws) > 1 else "") + "err "
                             + (f"{w.series.pos_error[-1]:.3f} m" if w.series.pos_error else "-")
                             for w in ws)
            c = self.series.robot_clearance[-1] if self.series.robot_clearance else float("nan")
            el = self.sim_time - t_sent
            wall = time.monotonic() - wall_sent
            rtf = el / wall if wall > 0 else float("nan")
            state = "/".join(NAMES.get(w.mob_state, str(w.mob_state)) for w in ws)
            progress.update(f"[mission] {name}: {state} t={el:5.1f}/{duration:.1f} s  {errs}  "
                            f"clear {c:.2f} m  {rtf:4.1f}x real time")

        # A controller that dies before its CONTROLLING state reaches us (its latched state
        # dies with it) shows up as the sim's watchdog fault: stop waiting then, too.
        self.spin_until(lambda: all(w.controlling_since(marks[w.name]) for w in ws) or faulted(),
                        30.0, lambda: "the controllers to accept their segments (" + ", ".join(
                            w.named for w in ws if not w.controlling_since(marks[w.name]))
                        + " did not)", tick)
        if self.handover:       # every controller holds its segment: the sim may run
            self._run_chunks(ws, marks, duration, wall_timeout, tick)
            if any(w.faults for w in ws):
                fault_seen.update(sim=self.sim_time, wall=time.monotonic())
        else:
            self.spin_until(finished, wall_timeout, "the end of the flight", tick)
        res.sim_t1, res.wall_t1 = self.sim_time, time.time()
        res.sim_time = self.sim_time - t_sent
        if fault_seen:
            first = min(((w.faults[0][0], w) for w in ws if w.faults), key=lambda x: x[0])[1]
            raise MissionError(f"flight aborted on a fault of {first.named}: {first.faults[0][1]}"
                               if len(ws) > 1 else f"flight aborted on a fault: {first.faults[0][1]}")
        t_acc = min(next(t for t, s, _ in w.mob_changes[marks[w.name]:] if s == CONTROLLING)
                    for w in ws)
        if self.handover:       # the flight starts at the hand-over time, after the lead
            t_acc = max(t_acc, t_sent + HANDOVER_LEAD)
        res.duration = max(w.done_since(marks[w.name]) for w in ws) - t_acc
        wall = time.monotonic() - wall_sent
        res.real_time_factor = res.sim_time / wall if wall > 0 else None

    def _watch_peers(self, ws: list[RobotWatch]) -> None:
        """Watch the sim, the planner and the controllers of this leg's robots (the nodes
        publishing their /mob/state) from now on."""
        me = self.node.get_fully_qualified_name()
        ctls = sorted({e.node_fqn for w in ws for e in self.node.get_publishers_info_by_topic(
            mc.robot_topic(w.name, sm.MOB_STATE)) if e.node_fqn != me})
        self.peers = PeerWatch(self.node, nodes=[*PEERS, *ctls])

    def _plan_one(self, w: RobotWatch, info: Any, fm: Any, goal_p, goal_q, res: LegResult):
        """PlanGlobal for one robot: ([segment], duration)."""
        pos, q = w.pose
        req = self.roszen.request_class("astrobee_msgs/srv/PlanGlobal")()
        _set_pose(req.start, pos, q)
        _set_pose(req.goal, goal_p, goal_q)
        req.flight_mode = fm.name
        req.face_forward = bool(info.face_forward)
        # the cargo bag trails along the path: the scenario's margin (bags.yaml's carry_extent default)
        req.carry_extent = float(info.carry_extent) if info.carrying_bag else 0.0
        res.carry_extent = req.carry_extent
        plan = self.call(self.planner, req, 120.0, mc.PLANNER_GLOBAL)
        res.planning_time = float(plan.planning_time)
        if not plan.success:
            raise MissionError(f"planning failed (code {plan.code}): {plan.message}")
        self.log.info(f"{info.name}: plan of {plan.duration:.1f} s in {plan.planning_time:.2f} s, "
                      f"{len(plan.segment)} states")
        seg = self.roszen.message_class("astrobee_msgs/msg/Segment")()
        seg.header.stamp = self.node.get_clock().now().to_msg()
        seg.header.frame_id = "world"
        seg.flight_mode = fm.name
        seg.segment = list(plan.segment)
        if self.handover:        # starts at a fixed sim time (the plan's times start at 0)
            t0 = self.sim_time + HANDOVER_LEAD
            for s in seg.segment:
                mc.set_stamp_ns(s.when, mc.stamp_ns(s.when) + mc.to_ns(t0))
            mc.set_stamp(seg.header.stamp, t0)
        return [seg], float(plan.duration)

    def _plan_formation(self, ws: list[RobotWatch], info: Any, fm: Any, goal_p, goal_q,
                        res: LegResult):
        """PlanFormation for two robots holding the cargo bag: (one segment per robot, all with
        the same start stamp a moment ahead, duration)."""
        req = self.roszen.request_class("astrobee_msgs/srv/PlanFormation")()
        req.robots = [w.name for w in ws]
        poses = []
        for w in ws:
            m = self.roszen.message_class("geometry_msgs/msg/Pose")()
            _set_pose(m, *w.pose)
            poses.append(m)
        req.starts = poses
        _set_pose(req.goal, goal_p, goal_q)
        if info.carrying_bag and self.bag_state is not None:
            req.has_bag_pose = True
            req.bag_pose = self.bag_state.pose
            req.bag_size = info.bag_size
        req.flight_mode = fm.name
        t_start = self.sim_time + (HANDOVER_LEAD if self.handover else FORMATION_LEAD)
        mc.set_stamp(req.start_time, t_start)
        plan = self.call(self.formation, req, 120.0, mc.PLANNER_FORMATION)
        res.planning_time = float(plan.planning_time)
        if not plan.success:
            raise MissionError(f"formation planning failed (code {plan.code}): {plan.message}")
        self.log.info(f"{info.name}: formation plan of {plan.duration:.1f} s in "
                      f"{plan.planning_time:.2f} s: {'; '.join(plan.steps)}")
        for w, seg in zip(ws, plan.segments):
            end = seg.segment[-1].pose
            self._goals[w.name] = mc.pose(end)
        return list(plan.segments), float(plan.duration)

    def _finish(self, res: LegResult) -> None:
        ws = [self.watches[n] for n in self.flying]
        s = self.series
        for k, v in s.tracking().items():
            setattr(res, k, v if v == v else None)
        cl = s.clearance()
        res.min_robot_clearance, res.min_bag_clearance = cl["min_robot_clearance"], cl["min_bag_clearance"]
        res.contacts = cl["contact_samples"]
        res.contact_bodies = sorted(s.contact_bodies)
        robots = []
        for w in ws:
            r = sm.RobotResult(name=w.name, start=self._starts.get(w.name, []))
            goal = self._goals.get(w.name)
            if goal is not None:
                r.goal = [*goal[0].tolist(), *rot.normalize(goal[1]).tolist()]
                if w.pose is not None:
                    r.final_position_error = float(np.linalg.norm(w.pose[0] - goal[0]))
                    r.final_attitude_error = float(rot.angle_between(w.pose[1], rot.normalize(goal[1])))
            for k, v in w.series.tracking().items():
                setattr(r, k, v if v == v else None)
            r.min_clearance = w.series.robot_min_clearance()
            r.contacts = s.contact_samples(sm.contact_name(w.name))
            r.faults = [text for _, text in w.faults]
            robots.append(r)
        aborted = res.reason
        res.success, res.reason = sm.leg_verdict(robots, res.tolerance_position, res.tolerance_attitude,
                                                 s.contact_samples("bag"), aborted)
        for w, r in zip(ws, robots):
            if r.success:
                continue
            if w.faults:
                t, why = w.faults[0][0], f"fault: {w.faults[0][1]}"
            elif r.contacts:
                t, why = s.first_contact(sm.contact_name(w.name)), "touched the station"
            elif aborted:       # not the cause: it stopped with the leg
                r.reason = f"stopped with the aborted leg ({r.reason})"
                continue
            else:
                t, why = w.sim_time, r.reason
            if t is not None and t == t:
                r.failed_at = {"t": t, "position": w.position_at(t), "why": why}
        res.robots = [asdict(r) for r in robots]
        res.realism = dict(self.realism.get("knobs") or {})
        res.disturbances = list(self.realism.get("applied") or [])
        res.faults = [text if len(ws) == 1 else f"{w.named}: {text}"
                      for w in ws for _, text in w.faults]
        lead = robots[0] if robots else None
        if lead is not None:
            errs = [r.final_position_error for r in robots]
            atts = [r.final_attitude_error for r in robots]
            res.final_position_error = None if None in errs else max(errs)
            res.final_attitude_error = None if None in atts else max(atts)
            rms = [r.rms_position_error for r in robots if r.rms_position_error is not None]
            res.rms_position_error = max(rms) if rms else None


def _set_pose(dst: Any, p: np.ndarray, q: np.ndarray) -> None:
    dst.position.x, dst.position.y, dst.position.z = (float(v) for v in p)
    dst.orientation.x, dst.orientation.y, dst.orientation.z, dst.orientation.w = (float(v) for v in q)


def write_outputs(run_dir: Path, legs: list[LegResult], series: list[dict[str, sm.Series]],
                  status: str) -> dict[str, Any]:
    """summary.json and one plot per leg (every robot of the leg) in run_dir."""
    run_dir.mkdir(parents=True, exist_ok=True)
    boxes = config.keep_in_boxes()
    for leg, per in zip(legs, series):
        if any(s.position for s in per.values()):
            name = "plot.png" if len(legs) == 1 else f"plot_{leg.scenario}.png"
            try:
                sm.plot(per, run_dir / name, boxes,
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
    sm.write_json(run_dir / "summary.json", data)
    return data


def run_mission(scenarios: list[str], run_dir: Path, namespace: str = "",
                argv: list[str] | None = None, wall_timeout: float = 600.0,
                ready_timeout: float = 90.0, stream=None, handover: bool = False,
                await_recorder: bool = False) -> int:
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
    client = MissionClient(node, namespace, stop_flag=lambda: stop["flag"], handover=handover,
                           await_recorder=await_recorder)
    progress = Progress(stream)
    legs: list[LegResult] = []
    all_series: list[dict[str, sm.Series]] = []
    status = "completed"
    code = 0
    try:
        for i, name in enumerate(scenarios):
            try:
                res = client.fly(name, reset=i > 0, progress=progress, wall_timeout=wall_timeout,
                                 ready_timeout=ready_timeout)
            except Interrupted:
                legs.append(getattr(client, "interrupted_result", None) or client_last(client, name))
                all_series.append(client.leg_series())
                status, code = "interrupted", 130
                break
            legs.append(res)
            all_series.append(client.leg_series())
            for w in client.watches.values():   # samples after this leg's end belong to no leg
                w.series = sm.Series()
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
    # the last line names the cause: the launcher quotes it as the run's cause when we fail
    print(f"[mission] summary: {Path(run_dir) / 'summary.json'} "
          f"({'success' if data['success'] else status + ': ' + str(data.get('reason', ''))})",
          file=stream or sys.stdout, flush=True)
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
    p.add_argument("--namespace", default="", help="robot namespace of a one-robot scenario "
                   "(a scenario's robots come from /sim/scenario)")
    p.add_argument("--timeout", type=float, default=600.0, help="wall seconds per leg")
    p.add_argument("--handover", action="store_true",
                   help="deterministic lockstep: the sim was started paused (sim_node "
                        "start_paused); each leg reset, handed over at a fixed sim time, run "
                        "in chunks")
    p.add_argument("--await-recorder", action="store_true",
                   help="with --handover: wait for a bag recorder on every topic of the sim")
    a = p.parse_args(own)
    try:
        for name in a.scenario:
            Scenario.load(name)
    except (ScenarioError, config.ConfigError) as exc:
        print(f"astrobee mission: {exc}", file=sys.stderr)
        return 2
    run_dir = Path(a.run_dir) if a.run_dir else Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    return run_mission(a.scenario, run_dir, a.namespace, ["mission", *ros], wall_timeout=a.timeout,
                       handover=a.handover, await_recorder=a.await_recorder)


if __name__ == "__main__":
    sys.exit(main())
