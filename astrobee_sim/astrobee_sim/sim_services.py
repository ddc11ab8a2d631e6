"""sim_node's services: /sim/reset, /sim/control (PAUSE, RESUME [steps], STEP), and the flight
mode's /sim/set_flight_mode (every robot) and <ns>/mob/set_flight_mode (one robot).

A bad request is refused with success false and a one-line message (at most MAX_REPLY
characters of what was asked echoed back) and changes nothing: the backend validates a reset
whole before it clears the running world.
"""
from __future__ import annotations

from typing import Any

from astrobee import config, flight_modes
from astrobee import msgconv as mc
from astrobee.scenario import ScenarioError

MAX_CONTROL_STEPS = 100_000     # one /sim/control STEP request (~5 min of sim at 350 Hz)
MAX_REPLY = 400                 # characters of a refused request echoed in a reply


def _short(text: str) -> str:
    return text if len(text) <= MAX_REPLY else text[:MAX_REPLY] + "..."


class SimServices:
    """The service handlers of one SimNode (see the module docstring); they never raise."""

    def __init__(self, host: Any) -> None:
        """host: the SimNode (node, sim, names, loop, state, latched, commands, now_ns(),
        warn(), log, add_robots())."""
        from roszen import runtime as roszen
        self.host = host
        self.response = roszen.response_class
        self.robots: set[str] = set()
        n = host.node
        n.create_service("astrobee_msgs/srv/Reset", mc.SIM_RESET, self.on_reset)
        n.create_service("astrobee_msgs/srv/SetFlightMode", "/sim/set_flight_mode",
                         lambda req: self.on_set_mode(req, None))
        n.create_service("astrobee_msgs/srv/SimControl", mc.SIM_CONTROL, self.on_control)

    def add_robot(self, name: str) -> None:
        """A robot's <ns>/mob/set_flight_mode (once per robot name)."""
        if name not in self.robots:
            self.robots.add(name)
            self.host.node.create_service("astrobee_msgs/srv/SetFlightMode",
                                          mc.robot_topic(name, mc.SET_FLIGHT_MODE),
                                          lambda req, nm=name: self.on_set_mode(req, nm))

    def on_set_mode(self, req: Any, robot: str | None) -> Any:
        host = self.host
        resp = self.response("astrobee_msgs/srv/SetFlightMode")()
        if robot is not None and robot not in host.names:
            resp.success, resp.message = False, f"robot {robot!r} is not in the current scenario"
            return resp
        try:
            host.sim.set_flight_mode(req.flight_mode, robot)
        except flight_modes.UnknownFlightMode as exc:
            resp.success, resp.message = False, _short(str(exc))
            return resp
        host.latched.publish_modes()
        resp.success, resp.message = True, f"flight mode {req.flight_mode}"
        return resp

    def on_reset(self, req: Any) -> Any:
        host = self.host
        resp = self.response("astrobee_msgs/srv/Reset")()
        try:
            # the backend validates the whole request (name, file, seed) before it clears the
            # world: a refused reset leaves the running world as it was
            host.sim.reset(req.scenario or None, req.seed)
        except (ScenarioError, config.ConfigError, ValueError, TypeError) as exc:
            resp.success, resp.message = False, _short(f"reset refused: {exc}")
            host.warn("reset", resp.message, every=0.5)
            return resp
        host.restarted()
        resp.success, resp.message = True, f"reset to {host.sim.scenario.name} (seed {host.sim.seed})"
        host.log.info(resp.message)
        return resp

    def on_control(self, req: Any) -> Any:
        host, loop = self.host, self.host.loop
        resp = self.response("astrobee_msgs/srv/SimControl")()
        if req.command == mc.SimControl.PAUSE:
            loop.pause()
            resp.message = "paused"
        elif req.command == mc.SimControl.RESUME:
            steps = int(req.steps)
            if steps > MAX_CONTROL_STEPS:
                resp.success = False
                resp.message = f"steps {steps} > {MAX_CONTROL_STEPS}: ask for fewer per request"
                return resp
            t_pause = loop.resume(steps)
            resp.message = "resumed"
            if t_pause is not None:              # a budget of physics steps, then pause again
                resp.success = True
                mc.set_stamp_ns(resp.sim_time, mc.to_ns(t_pause))
                resp.message = f"resumed until t={t_pause:.3f} s"
                return resp
        elif req.command == mc.SimControl.STEP:
            if not loop.paused:
                resp.success, resp.message = False, "STEP needs a paused simulation (send PAUSE first)"
                return resp
            steps = max(1, int(req.steps))
            if steps > MAX_CONTROL_STEPS:
                resp.success = False
                resp.message = f"steps {steps} > {MAX_CONTROL_STEPS}: ask for fewer per request"
                return resp
            host.sim.step(steps)
            host.state.publish()
            resp.message = f"stepped {steps}"
        else:
            resp.success, resp.message = False, f"unknown command {req.command} (0 PAUSE, 1 RESUME, 2 STEP)"
            return resp
        resp.success = True
        mc.set_stamp_ns(resp.sim_time, host.now_ns())
        return resp
