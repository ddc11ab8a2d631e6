"""Bringing the simulator to a leg's scenario: a reset in a running sim, or (deterministic
lockstep) a reset of the paused sim once the graph is ready, and the /sim/control calls."""
from __future__ import annotations

import time
from typing import Any

from astrobee import msgconv as mc
from astrobee.scenario import Scenario
from astrobee_bringup.peers import relay_missing

from .result import MissionError


class SimResets:
    """The reset and sim-control part of the MissionClient (it provides node, roszen, call,
    spin_until, watch, watches, flying, scenario_info, sim_robots, await_recorder)."""

    def reset_to(self, name: str, ready_timeout: float) -> None:
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
            cmd = mc.robot_topic(r, mc.COMMAND)
            if w.mob_state is None:
                return f"{w.named}: no controller ({mc.robot_topic(r, mc.MOB_STATE)})"
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

