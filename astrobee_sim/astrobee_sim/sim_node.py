"""sim_node: a simulator backend served on the ROS 2 graph (thin wiring; physics lives behind the
SimBackend protocol of backend.py: `backend:=pybullet` (simulation.py, the default) or
`backend:=rigid` (rigid_backend.py, numpy rigid bodies, for graph tests)).

Per robot namespace <ns> ("" for the default robot): publishes <ns>/loc/truth/pose,
<ns>/loc/truth/twist (world-frame linear and angular velocity), <ns>/gnc/ekf (EkfState: world
velocity, BODY omega), latched <ns>/mob/flight_mode and <ns>/sim/fault (propulsion watchdog);
subscribes <ns>/gnc/ctl/command (FamCommand, BODY wrench); serves <ns>/mob/set_flight_mode.
Global: /clock, /tf, /sim/bag/state, /sim/bag/mesh (mesh_rate), /sim/contacts, latched
/sim/markers and /sim/scenario (ScenarioInfo: the scenario as built, republished after every
reset); services /sim/reset, /sim/set_flight_mode, /sim/control.

Realism (astrobee.realism): `realism` (a preset of config/realism.yaml; "" = the scenario's own,
off unless its YAML has a realism: section) plus `realism.<knob>` overrides of the scalar knobs
and one disturbance (`realism.disturbance_time` (< 0: drawn from the seed in 0..60 s),
`_target`, `_force` [x,y,z] or `_magnitude`, `_duration`, `_robot`). <ns>/gnc/ekf then carries
the noisy estimate (the truth topics stay truth); /sim/scenario's bag_mass is the mass the
controller is told (bag_mass_true the truth, realism the knobs as YAML); latched /sim/realism
(std_msgs/String, YAML: knobs, schedule, applied) is republished when a disturbance starts.

Parameters are checked at start: a bad one ends the node with one line naming it (exit 1). A
bad /sim/reset request (unknown scenario, a path for a name, a negative seed, an invalid
scenario file) is refused with success false and the running world keeps going untouched.

Clock modes: realtime (paced to the wall clock), fast (no pacing), lockstep (after publishing
the state of tick k the sim waits, at most `lockstep_timeout` s of wall time, for a command
stamped >= tick k on every robot whose command topic has a publisher; on timeout it logs and
steps on, the propulsion watchdog then acting as on the robot). Commands stamped more than
`command_max_lead` (0.5 s) ahead of sim time are dropped with a rate-limited warning: after a
reset sim time restarts at 0, so answers to pre-reset states land there; a reset also forgets
the lockstep command stamps, and a command counts for the current tick at most.

Deterministic lockstep (`start_paused:=true`, set by the launch when the mission runs in
lockstep): the sim starts paused and publishes no state (only /clock, every 0.5 s of wall)
until a client resets it; a reset leaves it paused with the state of t=0 published once; the
state is never republished while waiting for commands (every subscriber was there before the
first tick). /sim/control RESUME with `steps` > 0 runs until that many physics steps are done
(rounded up to a publish tick), then pauses again; its reply's sim_time is the time it will
pause at. The mission so hands a segment over at a fixed sim time and ends each leg at a tick
the flight fixes, not the wall clock.

Per-tick cost: the per-tick messages go out as CDR templates with their numbers packed in place
(tick_wire: the same bytes as serialising the message objects, checked when each layout is
first built), commands are read in place (tick_wire.decode_command), the wall clearance is one
compiled loop (world.py). At max_sim_time the node logs its own real-time factor since the
run's first tick, by the wall clock and per CPU second of this process (bench/sim_rtf.py reads it).

This module wires the parts, one job each: sim_params (parameters, checked), sim_commands (the
command inbox), state_publisher (the per-tick topics), latched_topics (the world as built),
sim_services (reset, control, flight mode), sim_loop (ticks, pausing, pacing, lockstep).
"""
from __future__ import annotations

import os
import sys
import time
from dataclasses import replace
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")    # before numpy: see astrobee_sim/__init__.py

from astrobee import config  # noqa: E402
from astrobee import msgconv as mc  # noqa: E402
from astrobee.scenario import Scenario, ScenarioError  # noqa: E402

from .backend import SimBackend, make_backend  # noqa: E402
from .latched_topics import LatchedTopics  # noqa: E402
from .sim_commands import CommandInbox  # noqa: E402
from .sim_loop import TickLoop  # noqa: E402
from .sim_params import ParameterError, SimOptions, read_options  # noqa: E402
from .sim_services import SimServices  # noqa: E402
from .state_publisher import StatePublisher  # noqa: E402

__all__ = ["ParameterError", "SimNode", "SimOptions", "build", "main", "read_options"]


class SimNode:
    """Wires a SimBackend to topics and services (the parts above); callbacks never raise."""

    def __init__(self, node: Any, backend: SimBackend, opts: SimOptions) -> None:
        self.node = node
        self.log = node.get_logger()
        self.sim = backend
        self.opts = opts
        self.names: list[str] = backend.robot_names()
        self._warned: dict[str, float] = {}
        self.state = StatePublisher(self, opts.mesh_rate)
        self.latched = LatchedTopics(self)
        self.commands = CommandInbox(self, opts.command_max_lead)
        self.loop = TickLoop(self, opts)
        self.services = SimServices(self)
        self.add_robots()
        self.latched.publish_markers()
        self.latched.publish_scenario()
        self.latched.publish_modes()
        if not opts.start_paused:      # paused: the first state comes with the client's reset
            self.state.publish()
        self.latched.publish_realism()
        bag = backend.scenario.bag
        self.log.info(f"sim up: scenario {backend.scenario.name}, robots {self.names}, "
                      f"bag {bag.model if bag else 'none'}, backend {opts.backend}, "
                      f"clock {opts.clock_mode}, physics {1.0 / backend.dt:g} Hz")

    def add_robots(self) -> None:
        """The per-robot publishers, subscription and service of every robot of the backend's
        current scenario that has none yet (a reset may bring new robot names)."""
        for name in self.names:
            self.state.add_robot(name)
            self.latched.add_robot(name)
            self.commands.add_robot(name)
            self.services.add_robot(name)

    def restarted(self) -> None:
        """After a successful reset: rewire for the new robots, forget the old run's command
        stamps and faults, restart the tick count, republish the world and its first state."""
        self.names = self.sim.robot_names()
        self.add_robots()
        self.commands.forget()
        self.state.forget()
        self.loop.restart()
        self.latched.publish_markers()
        self.latched.publish_scenario()
        self.latched.publish_modes()
        self.state.publish()
        self.latched.publish_realism()

    def now_ns(self) -> int:
        """Sim time in ns (the stamp of everything published now)."""
        return mc.to_ns(self.sim.time)

    def warn(self, key: str, text: str, every: float = 2.0) -> None:
        """Log a warning at most once every `every` s of wall time per key."""
        now = time.monotonic()
        if now - self._warned.get(key, -1e9) >= every:
            self._warned[key] = now
            self.log.warn(text)

    def run_tick(self) -> None:
        """One tick: wait (lockstep), step, publish."""
        self.loop.run_tick()

    def spin(self) -> None:
        self.loop.spin()

    def close(self) -> None:
        self.node.destroy_node()
        self.sim.close()


def build(argv: list[str]) -> SimNode:
    """The roszen node, its checked parameters, the backend they ask for, wired together.
    Raises ParameterError / ConfigError / ValueError (one line each) for a bad start."""
    from roszen import runtime as roszen
    node = roszen.Node("sim_node", argv=argv)
    backend = None
    try:
        opts = read_options(node)
        try:
            base = Scenario.load(opts.scenario)
        except ScenarioError as exc:
            raise ParameterError(f"parameter scenario: {exc}") from None
        sc = opts.overrides.apply(base)      # its ScenarioError names the override (robots, ...)
        overrides = opts.overrides
        try:
            realism = opts.realism_for(sc)
        except ScenarioError as exc:
            raise ParameterError(f"parameter realism: {exc}") from None
        if realism is not None:
            sc = sc.override(realism=realism)
            if opts.backend == "pybullet":
                overrides = replace(overrides, realism=realism)   # kept over /sim/reset by name
        if sc.realism.physical and opts.backend != "pybullet":
            raise ParameterError(f"parameter realism: backend {opts.backend} models no realism "
                                 f"but bag_mass_told; use backend:=pybullet")
        backend = make_backend(opts.backend, sc, opts.seed, physics_rate=opts.physics_rate,
                               gui=opts.gui, drag=opts.drag, overrides=overrides)
        from .world import min_sdf_kernel
        min_sdf_kernel(load=True)        # the compiled clearance: ~0.4 s now, ~30 us a tick less
        return SimNode(node, backend, opts)
    except BaseException:
        if backend is not None:
            backend.close()
        node.destroy_node()
        raise


def main(argv: list[str] | None = None) -> int:
    """Entry point (`ros2 run astrobee_sim sim_node`): exit 0 when stopped, 1 for a bad start."""
    from roszen.parameters import ParameterException
    from roszen.runtime import node_main
    return node_main.run(build, argv, errors=(config.ConfigError, ValueError, ParameterException),
                         prog="sim_node")


if __name__ == "__main__":
    sys.exit(main())
