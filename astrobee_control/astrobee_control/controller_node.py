"""controller_node: any ControlLaw (law.py) wired to the graph; the PD and MPC nodes are a few
lines on top of it.

Subscribes <ns>/gnc/ekf (default; or loc/truth/pose + loc/truth/twist with state_source:=truth),
<ns>/gnc/ctl/segment (latched), <ns>/mob/flight_mode (latched), /sim/bag/state and /sim/scenario
(latched: the carried bag's mass and size, unless the bag_mass / bag_size parameters say
otherwise). Publishes <ns>/gnc/ctl/command (FamCommand, BODY-frame wrench), <ns>/gnc/ctl/traj
(the reference, ControlState), <ns>/mob/state (MotionState, latched, on change and at 1 Hz) and,
for laws that sample candidates, <ns>/gnc/ctl/candidates (MarkerArray: the candidates and the
chosen one). Service <ns>/gnc/ctl/stop (std_srvs/Trigger): hold the current pose. The
messages out are built by its ControllerOutputs mixin (controller_outputs.py).

One command per state sample, stamped with the state's stamp: at 62.5 Hz when the sim
publishes at 62.5 Hz, on sim time in every clock mode (in lockstep the sim waits for it).

Peer loss (wall clock: /clock stops with the sim): when every publisher of the state topic has
left the graph (its liveliness token gone: the sim killed or cut off) the law stops and holds
the last pose, commands stop with the states, /mob/state says "lost node <name>: ..." and one
log line names it; when states stop coming for `state_timeout` wall seconds while the publisher
is still there (a paused or hung sim) /mob/state and one log line say so (INFO while the sim's
/clock still comes: a deliberate pause; WARN when it stopped too: a hang) and the law is left
alone (a paused sim resumes the segment). The first state afterwards re-holds its pose.

Parameters are either applied at run time (flight_mode, bag_mass, bag_size, truth_omega_frame,
candidates_rate, state_timeout, settle_time) or read-only (state_source, safety, safety_margin
and the law's others).

With `safety:=true` the node filters its own command through the CBF safety filter
(safety.LawFilter: the same filter, keep-in boxes, carried-bag extent and flight-mode limits as
safety_filter_node, with the state the law was given) before publishing it, and publishes the
filter's latched diagnostics on <ns>/gnc/ctl/safety as safety_filter_node does: no process and
no hop of its own in the lockstep loop.
"""
from __future__ import annotations

import time
from typing import Any, Callable

import numpy as np

from astrobee import flight_modes
from astrobee import msgconv as mc
from astrobee import rotations as rot
from roszen.runtime import node_main
from roszen.peers import PublisherWatch
from roszen.parameters import read_only, runtime

from . import mass as mp
from .controller_outputs import ControllerOutputs
from .law import ControlLaw, LawFactory
from .node_io import (CarriedBag, FlightModeParameter, SafetyDiagnostics, bag_descriptors,
                      ekf_state)
from .pd import State
from .reference import from_control_states

JUMP_DISTANCE = 0.5  # m between two state samples: a reset, not motion
CLOCK_HEARTBEAT = 1.5  # wall s: a paused sim's /clock comes every 0.5 s (sim_loop.PAUSED_CLOCK_PERIOD)

# parameters every controller node declares (name -> default)
COMMON_PARAMETERS: dict[str, Any] = {
    "state_source": "ekf",          # ekf | truth
    "flight_mode": flight_modes.get().name,   # config's default until /mob/flight_mode says
    "bag_mass": -1.0,               # kg; < 0 = the scenario's (from /sim/scenario)
    "bag_size": [0.0, 0.0, 0.0],    # m; zeros = the scenario's
    "truth_omega_frame": "world",   # frame of loc/truth/twist's angular velocity: world | body
    "candidates_rate": 2.0,         # Hz at most for /gnc/ctl/candidates (0: never)
    "state_timeout": 1.0,           # wall s without a state before /mob/state reports it stale
    "safety": False,                # filter the command through the CBF safety filter in-process
    "safety_margin": 0.05,          # m the filter's boundary sits outside the keep-in boxes
}
PREDICTED_PATH = "gnc/ctl/predicted_path"   # nav_msgs/Path of laws with predicted_path()
PEER_CHECK_PERIOD = 0.1             # wall s between two looks at the graph and the state's age


def _apply_settle_time(law: ControlLaw, value: float) -> None:
    """settle_time of the law's tracker (the PD law is one; the MPC holds one)."""
    if not value > 0:
        raise ValueError(f"settle_time must be > 0 s, got {value:g}")
    target = getattr(law, "tracker", law)
    if not hasattr(target, "settle_time"):
        raise ValueError(f"the {law.name} law has no settle time")
    target.settle_time = float(value)


# law parameters applied at run time (name -> apply(law, value)); the law's others are read-only
LAW_RUNTIME: dict[str, Callable[[ControlLaw, Any], None]] = {"settle_time": _apply_settle_time}


class ControllerNode(ControllerOutputs):
    """Wiring of one ControlLaw to topics; callbacks never raise (bad samples are logged and
    dropped)."""

    def __init__(self, make_law: LawFactory, node_name: str, parameters: dict[str, Any] | None = None,
                 argv: list[str] | None = None) -> None:
        from roszen import runtime as roszen
        from roszen.runtime import LATCHED

        self.roszen = roszen
        self.node = n = roszen.Node(node_name, argv=argv)
        self.log = n.get_logger()
        self.law: ControlLaw | None = None
        how = self._parameter_descriptors()
        values = {name: n.declare_parameter(name, default, how.get(name) or read_only()).value
                  for name, default in {**COMMON_PARAMETERS, **(parameters or {})}.items()}
        self.state_source = str(values["state_source"])            # checked by its descriptor
        self.truth_omega_frame = str(values["truth_omega_frame"])
        self.bag = CarriedBag(values["bag_mass"], values["bag_size"])
        self._set_candidates_rate(float(values["candidates_rate"]))
        self.state_timeout = float(values["state_timeout"])      # >= 0.05 s: its descriptor
        mode = flight_modes.get(str(values["flight_mode"]) or None)
        law_params = {k: values[k] for k in (parameters or {})}
        self.law: ControlLaw = make_law(mode, mp.robot(), law_params)
        self.safety = self._make_safety(values["safety"], values["safety_margin"])
        self.modes = FlightModeParameter(n, lambda m: self.law.set_flight_mode(m))
        self._last_stamp: float | None = None
        self._last_state: State | None = None
        self._last_segment_key: tuple[int, int] | None = None
        self._pending: dict[str, dict[tuple[int, int], Any]] = {"pose": {}, "twist": {}}
        self._last_mob_pub = -1e9
        self._last_candidates = -1e9
        self._last_path = -1e9
        self._carrying = False
        # peer watch (wall clock): who publishes our state, when the last state came, why lost
        self.state_pubs = PublisherWatch(n, mc.POSE if self.state_source == "truth" else mc.EKF)
        self.state_topic = self.state_pubs.topic     # resolved (namespace, remaps)
        self._last_state_wall: float | None = None
        self._lost = ""                 # why states stopped ("" while they come)
        self._gone = False              # ... because the state topic has no publisher left
        self._last_clock_wall: float | None = None     # wall s of the last /clock sample
        n.get_clock().add_listener(self._on_clock)

        M = roszen.message_class
        self.FamCommand, self.ControlState = M("astrobee_msgs/msg/FamCommand"), M("astrobee_msgs/msg/ControlState")
        self.MotionState = M("astrobee_msgs/msg/MotionState")
        self.MarkerArray, self.Marker = M("visualization_msgs/msg/MarkerArray"), M("visualization_msgs/msg/Marker")
        self.Point = M("geometry_msgs/msg/Point")
        self.pub_cmd = n.create_publisher("astrobee_msgs/msg/FamCommand", mc.COMMAND, 10)
        self.pub_traj = n.create_publisher("astrobee_msgs/msg/ControlState", mc.TRAJ, 10)
        self.pub_mob = n.create_publisher("astrobee_msgs/msg/MotionState", mc.MOB_STATE, LATCHED)
        self.pub_cand = n.create_publisher("visualization_msgs/msg/MarkerArray", mc.CANDIDATES, 2)
        # a law that predicts its own motion (predicted_path(): (K, 3) world) publishes it as a
        # nav_msgs/Path at the candidates' rate
        self.pub_path = None
        if callable(getattr(self.law, "predicted_path", None)):
            self.Path, self.PoseStamped = M("nav_msgs/msg/Path"), M("geometry_msgs/msg/PoseStamped")
            self.pub_path = n.create_publisher("nav_msgs/msg/Path", PREDICTED_PATH, 2)
        n.create_subscription("astrobee_msgs/msg/Segment", mc.SEGMENT, self._on_segment, LATCHED)
        n.create_subscription("astrobee_msgs/msg/FlightMode", mc.FLIGHT_MODE, self._on_flight_mode, LATCHED)
        n.create_subscription("astrobee_msgs/msg/BagState", mc.BAG_STATE, self._on_bag, 10)
        n.create_subscription("astrobee_msgs/msg/ScenarioInfo", mc.SIM_SCENARIO, self._on_scenario, LATCHED)
        if self.state_source == "truth":
            n.create_subscription("geometry_msgs/msg/PoseStamped", mc.POSE,
                                  lambda m: self._pair("pose", m), 10)
            n.create_subscription("geometry_msgs/msg/TwistStamped", mc.TWIST,
                                  lambda m: self._pair("twist", m), 10)
        else:
            n.create_subscription("astrobee_msgs/msg/EkfState", mc.EKF, self._on_ekf, 10)
        self.Trigger = roszen.response_class("std_srvs/srv/Trigger")
        n.create_service("std_srvs/srv/Trigger", mc.CTL_STOP, self._on_stop)
        n.create_timer(PEER_CHECK_PERIOD, self._watch_peers, clock=roszen.Clock(False))
        self.safety_diagnostics = None
        if self.safety is not None:
            self.safety_diagnostics = SafetyDiagnostics(n, self.safety)
        self._publish_mob("", force=True)
        self.log.info(f"{self.law.name} controller up: flight mode {self.law.flight_mode.name}, "
                      f"state from {self.state_source}"
                      + (f", CBF safety filter in-process (margin {self.safety.filter.margin:.2f} m)"
                         if self.safety is not None else ""))

    def _make_safety(self, on: Any, margin: Any) -> Any:
        """The in-process safety filter (safety.LawFilter) when `on`, else None."""
        if not isinstance(on, bool):
            raise ValueError(f"safety must be true or false, not {on!r}")
        if not on:
            return None
        from .safety.law_filter import LawFilter, check_margin
        return LawFilter(self.law.flight_mode, mp.robot(), margin=check_margin(margin))

    # ---- parameters -------------------------------------------------------------------
    def _parameter_descriptors(self) -> dict[str, Any]:
        """How each parameter applied at run time is applied (every other one is read-only)."""
        def law_param(name: str) -> Any:
            return runtime(lambda v: LAW_RUNTIME[name](self.law, v), min_value=1e-3
                           if name == "settle_time" else None)

        def flight_mode(v: str) -> None:
            self.law.set_flight_mode(flight_modes.get(str(v) or None))

        def set_attr(obj: Callable[[], Any], attr: str, convert: Callable) -> Callable:
            return lambda v: setattr(obj(), attr, convert(v))

        return {
            "flight_mode": runtime(flight_mode, choices=flight_modes.names()),
            **bag_descriptors(lambda: self.bag),
            "state_source": read_only(choices=("ekf", "truth")),
            "truth_omega_frame": runtime(set_attr(lambda: self, "truth_omega_frame", str),
                                         choices=("world", "body")),
            "candidates_rate": runtime(self._set_candidates_rate, min_value=0.0),
            "state_timeout": runtime(set_attr(lambda: self, "state_timeout", float),
                                     min_value=0.05),
            **{name: law_param(name) for name in LAW_RUNTIME},
        }

    def _set_candidates_rate(self, rate: float) -> None:
        self.candidates_period = 1.0 / rate if rate > 0 else float("inf")

    # ---- peers ------------------------------------------------------------------------
    def _watch_peers(self) -> None:
        """Wall-clock check: the state's publishers still in the graph, the last state recent."""
        if self._last_state_wall is None or self._gone:
            self.state_pubs.publishers()
            return
        loss = self.state_pubs.loss()
        who = self.state_pubs.who
        if loss is not None:
            if loss.pending:
                return      # a dead process's tokens leave one by one: its node token may lag
            if not loss.node_left:
                # e.g. the sim reset to a scenario without this robot: not a lost node
                self._lost = f"no publisher of {self.state_topic} ({who} stopped publishing it)"
                self.log.warn(f"{self._lost}; stopping (holding the last pose)")
            else:
                self._lost = f"lost node {who}: no publisher of {self.state_topic}"
                self.log.error(f"{self._lost}; stopping (holding the last pose)")
            self._gone = True
            if self.law.state != mc.MotionState.IDLE and self._last_state is not None:
                self.law.stop(self._last_state, self._last_stamp or 0.0, self._lost)
            self._publish_mob(self._lost, force=True, log=False)
        elif time.monotonic() - self._last_state_wall > self.state_timeout:
            self._stalled(who)

    def _on_clock(self, _ns: int) -> None:
        self._last_clock_wall = time.monotonic()

    def _stalled(self, who: str) -> None:
        """States stopped, their publisher still there. The sim's /clock still coming (a paused
        lockstep sim sends one every 0.5 wall s; a sim flying other robots, one a tick) is a
        deliberate pause: said at INFO; no /clock either is a hang: WARN, once."""
        last = self._last_clock_wall
        if last is not None and last > self._last_state_wall and \
                time.monotonic() - last <= self.state_timeout + CLOCK_HEARTBEAT:
            if not self._lost:
                self._lost = (f"no state on {self.state_topic} from {who}; its /clock goes on: "
                              f"paused (or flying other robots)")
                self.log.info(self._lost)
                self._publish_mob(self._lost, force=True, log=False)
            return
        if self._lost.startswith(f"no state on {self.state_topic} from {who} for"):
            return                                          # the hang is said already
        self._lost = (f"no state on {self.state_topic} from {who} for "
                      f"{self.state_timeout:g} s (wall): paused or hung?")
        self.log.warn(self._lost)
        self._publish_mob(self._lost, force=True, log=False)

    def _state_back(self, state: State) -> None:
        """The first state after a loss or a stall: say so; after a loss hold its pose."""
        gone, self._lost, self._gone = self._gone, "", False
        self.log.info(f"state back on {self.state_topic}")
        if gone:
            self.law.rehold(state, f"state back on {self.state_topic}: holding the pose")
            self._last_segment_key = None

    # ---- inputs -----------------------------------------------------------------------
    def _on_scenario(self, msg: Any) -> None:
        try:
            self.bag.on_scenario(msg)
        except (AttributeError, TypeError, ValueError) as exc:
            self.log.warn(f"bad scenario description dropped: {exc}")
            return
        if self.bag.scenario:
            self.log.info(f"scenario {msg.name}: carrying a {msg.bag_model} bag of "
                          f"{msg.bag_mass:.1f} kg")

    def _on_segment(self, msg: Any) -> None:
        try:
            key = mc.stamp_key(msg.header.stamp)
            if key == self._last_segment_key and key != (0, 0):
                return  # latched redelivery of the segment we already follow
            traj = from_control_states(msg.segment)
            if msg.flight_mode:
                self.modes.in_effect(flight_modes.get(msg.flight_mode))
        except (ValueError, AttributeError, TypeError) as exc:
            self.log.error(f"segment rejected: {exc}")
            self._publish_mob(f"segment rejected: {exc}", force=True)
            return
        self._last_segment_key = key
        now = self._last_stamp if self._last_stamp is not None else self._now()
        self.law.follow(traj, now)
        self.log.info(f"following a segment of {len(msg.segment)} states, {traj.duration:.1f} s")
        # said at once (not at the next state): a paused sim's client waits for it to resume
        self._publish_mob(f"segment of {traj.duration:.1f} s accepted", force=True, log=False)

    def _on_flight_mode(self, msg: Any) -> None:
        try:
            if self.modes.on_announced(msg.name):   # the flight_mode parameter shows it
                self.log.info(f"flight mode {msg.name}")
        except flight_modes.UnknownFlightMode as exc:
            self.log.error(str(exc))

    def _on_bag(self, msg: Any) -> None:
        try:
            state = self._last_state
            obs = self.bag.observe(msg) if state is not None else None
        except (ValueError, AttributeError, TypeError) as exc:
            self.log.warn(f"bad bag state dropped: {exc}")
            return
        if self.safety is not None:       # the filter's envelope: the held bag's extent
            self.safety.observe_bag(obs, state)
        if obs is None:
            if self._carrying:
                self.law.observe_bag(None, state)
                self._carrying = False
                self.log.info("bag released: robot mass only")
            return
        self.law.observe_bag(obs, state)
        if not self._carrying:
            offset, _ = obs.offset_in(state)
            self.log.info(f"bag attached: {obs.mass:.1f} kg at "
                          f"{np.round(offset, 3).tolist()} m (body frame)")
        self._carrying = True

    def _on_ekf(self, msg: Any) -> None:
        try:
            state = ekf_state(msg)
        except (AttributeError, TypeError, ValueError) as exc:
            self.log.warn(f"bad EKF state dropped: {exc}")
            return
        self._control(state, msg.header.stamp)

    def _pair(self, kind: str, msg: Any) -> None:
        """Pose and twist of one stamp make one state (either may come first)."""
        other_kind = "twist" if kind == "pose" else "pose"
        mine, other = self._pending[kind], self._pending[other_kind]
        key = mc.stamp_key(msg.header.stamp)
        if key not in other:
            mine[key] = msg
            if len(mine) > 20:
                del mine[min(mine)]
            return
        peer = other.pop(key)
        pose, twist = (msg, peer) if kind == "pose" else (peer, msg)
        for d in (mine, other):
            for old in [k for k in d if k < key]:
                del d[old]
        try:
            q = mc.quat(pose.pose.orientation)
            omega = mc.vec(twist.twist.angular)
            if self.truth_omega_frame == "world":
                omega = rot.rotate_inverse(q, omega)
            state = State(mc.vec(pose.pose.position), mc.vec(twist.twist.linear), q, omega)
        except (AttributeError, TypeError, ValueError) as exc:
            self.log.warn(f"bad truth state dropped: {exc}")
            return
        self._control(state, pose.header.stamp)

    def _on_stop(self, req: Any) -> Any:
        resp = self.Trigger()
        if self._last_state is None:
            resp.success, resp.message = False, "no state received yet: nothing to stop"
            return resp
        self.law.stop(self._last_state, self._last_stamp or 0.0)
        resp.success, resp.message = True, "stopping: holding the current pose"
        self.log.info("stop requested")
        return resp

    # ---- control ----------------------------------------------------------------------
    def _now(self) -> float:
        return self.node.get_clock().now().nanoseconds * 1e-9

    def _control(self, state: State, stamp: Any) -> None:
        vals = np.concatenate([state.position, state.velocity, state.orientation, state.omega])
        if not np.all(np.isfinite(vals)) or np.linalg.norm(state.orientation) < 1e-6:
            self.log.warn("non-finite state dropped")
            return
        state.orientation = rot.normalize(state.orientation)
        self._last_state_wall = time.monotonic()
        if not self.state_pubs.names:        # the first states: name their publisher now (a sim
            self.state_pubs.publishers()     # killed before the next graph check stays named)
        if self._lost:
            self._state_back(state)
        t = mc.stamp_s(stamp)
        last = self._last_state
        if last is not None and self._last_stamp is not None and (
                t < self._last_stamp - 1e-6
                or float(np.linalg.norm(state.position - last.position)) > JUMP_DISTANCE):
            self.law.rehold(state, "state jumped (simulation reset?): holding the new pose")
            self._last_segment_key = None
        dt = 1.0 / 62.5 if self._last_stamp is None else min(max(t - self._last_stamp, 0.0), 0.1)
        self._last_stamp, self._last_state = t, state
        step = self.law.update(state, t, dt)
        self._publish_command(step, stamp, self._filtered(step, state, stamp, t))
        self._publish_traj(step, stamp)
        self._publish_candidates(step, stamp, t)
        self._publish_path(stamp, t)
        self._publish_mob(step.event, force=bool(step.event))

    def _filtered(self, step: Any, state: State, stamp: Any, t: float) -> Any:
        """(force, torque) through the in-process safety filter, or None without one. A filter
        error (a non-finite law output) sends the maximum braking wrench and says so."""
        lf = self.safety
        if lf is None:
            return None
        if lf.mode is not self.law.flight_mode:     # a segment's, a topic's or a parameter's
            lf.set_flight_mode(self.law.flight_mode)
        try:
            res = lf.apply(step.output.force, step.output.torque, state)
        except (ValueError, ArithmeticError) as exc:
            self.log.warn(f"safety filter: {exc}: sending the maximum braking wrench")
            return lf.filter.braking_wrench(state.velocity, state.omega, state.orientation)
        self.safety_diagnostics.publish(res, stamp, t)
        return res.force, res.torque


def main(make_law: LawFactory, node_name: str, parameters: dict[str, Any] | None = None,
         argv: list[str] | None = None) -> int:
    """Entry point body of a controller executable: build the node around `make_law` and spin.

    `parameters` (name -> default) are declared as ROS parameters and handed to make_law, which
    raises ValueError with one line for bad values (the node then exits 1 with that line)."""
    return node_main.run(lambda a: ControllerNode(make_law, node_name, parameters, a), argv)


def run_registered(name: str, argv: list[str] | None = None) -> int:
    """Entry point body of the registered law `name` (astrobee_control.registry): its factory
    and parameters on a node named <name>_controller_node (unless remapped)."""
    from .registry import get
    law = get(name)
    return main(law.make_law, law.node_name, dict(law.params()), argv)


def generic_main(argv: list[str] | None = None) -> int:
    """`controller_node LAW [--ros-args ...]`: any registered law by name (the launcher runs a
    law that has no executable of its own this way)."""
    import sys
    from .registry import UnknownController, get
    argv = sys.argv if argv is None else argv
    plain = [a for a in argv[1:argv.index("--ros-args") if "--ros-args" in argv else len(argv)]]
    prog = "controller_node"
    if len(plain) != 1:
        print(f"{prog}: error: give the law's name: controller_node LAW [--ros-args ...]",
              file=sys.stderr)
        return 2
    try:
        get(plain[0])
    except UnknownController as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 1
    return run_registered(plain[0], argv)
