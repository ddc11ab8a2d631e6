"""The mission's node: per-robot watches, the cargo bag and contacts, the planner and sim
clients, and the waiting (spin until, with lost peers and SIGINT checked)."""
from __future__ import annotations

import time
from typing import Any

import numpy as np

from astrobee import msgconv as mc
from astrobee.leg_samples import LegSamples
from astrobee_bringup.series import Series
from roszen.peers import PeerLost, PeerWatch

from .resets import SimResets
from .result import Interrupted, MissionError
from .watch import FAULT_WATCH_SIM, FAULT_WATCH_WALL, RobotWatch

PEERS = ("sim_node", "planner_node")     # nodes every leg needs (plus its controllers)


class MissionClient(SimResets):
    """The mission's node: per-robot watches, the cargo bag and contacts, planner and reset
    clients."""

    def __init__(self, node: Any, namespace: str = "", stop_flag=None, handover: bool = False,
                 await_recorder: bool = False) -> None:
        from roszen import runtime as roszen
        from roszen.runtime import Durability, QoSProfile

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
        self.leg: LegSamples | None = None          # the current leg's samples
        self.cargo_state: Any = None
        self.scenario_info: Any = None      # the sim's latched /sim/scenario (ScenarioInfo)
        node.create_subscription("astrobee_msgs/msg/ScenarioInfo", mc.SIM_SCENARIO,
                                 self._on_scenario, self.latched)
        node.create_subscription("astrobee_msgs/msg/Contacts", mc.CONTACTS, self._on_contacts, 10)
        self.realism: dict = {}
        node.create_subscription("std_msgs/msg/String", "/sim/realism", self._on_realism, self.latched)
        node.create_subscription("astrobee_msgs/msg/BagState", mc.BAG_STATE, self._on_cargo, 10)
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
    def series(self) -> Series:
        """The first robot's series of the current leg (with the contacts and cargo bag)."""
        return self.watches[self.flying[0]].series

    def leg_series(self) -> dict[str, Series]:
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
        if self.leg is not None:
            self.leg.add_contacts(msg)

    def _on_cargo(self, msg: Any) -> None:
        self.cargo_state = msg
        for n in self.flying:
            self.watches[n].series.add_cargo(msg)
        if self.leg is not None:
            self.leg.add_cargo(msg)

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

    def watch_peers(self, ws: list[RobotWatch]) -> None:
        """Watch the sim, the planner and the controllers of this leg's robots (the nodes
        publishing their /mob/state) from now on."""
        me = self.node.get_fully_qualified_name()
        ctls = sorted({e.node_fqn for w in ws for e in self.node.get_publishers_info_by_topic(
            mc.robot_topic(w.name, mc.MOB_STATE)) if e.node_fqn != me})
        self.peers = PeerWatch(self.node, nodes=[*PEERS, *ctls])

