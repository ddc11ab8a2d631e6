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
lockstep): the sim starts paused and publishes no state (only /clock, once a second of wall)
until a client resets it; a reset leaves it paused with the state of t=0 published once; the
state is never republished while waiting for commands (every subscriber was there before the
first tick). /sim/control RESUME with `steps` > 0 runs until that many physics steps are done
(rounded up to a publish tick), then pauses again; its reply's sim_time is the time it will
pause at. The mission so hands a segment over at a fixed sim time and ends each leg at a tick
the flight fixes, not the wall clock.

Per-tick cost (issue 12): the per-tick messages go out as CDR templates with their numbers packed
in place (tick_wire: the same bytes as serialising the message objects, checked when each layout
is first built), commands are read in place (decode_command), the wall clearance is one compiled
loop (world.py). At max_sim_time the node logs its own real-time factor since the run's first
tick, by the wall clock and per CPU second of this process (bench/sim_rtf.py reads it).
"""
from __future__ import annotations

import math
import os
import struct
import sys
import time
from dataclasses import dataclass
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")    # before numpy: see astrobee_sim/__init__.py

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from astrobee import config, flight_modes  # noqa: E402
from astrobee import msgconv as mc  # noqa: E402
from astrobee import scenario as scn  # noqa: E402
from astrobee.realism import Disturbance, Realism  # noqa: E402
from astrobee.scenario import Scenario, ScenarioError  # noqa: E402

from . import markers, tick_wire  # noqa: E402
from .backend import BACKENDS, SimBackend, make_backend  # noqa: E402
from .robot import qrot_floats  # noqa: E402
from .simulation import sim_defaults  # noqa: E402

FAULT_WATCHDOG = 1
CLOCK_MODES = ("realtime", "fast", "lockstep")
MAX_CONTROL_STEPS = 100_000     # one /sim/control STEP request (~5 min of sim at 350 Hz)
MAX_REPLY = 400                 # characters of a refused request echoed in a reply
BAG_MARKER = "/sim/bag/marker"   # visualization_msgs/Marker TRIANGLE_LIST: the cargo bag's surface
ROBOT_MARKERS = "/sim/robot_markers"   # latched MarkerArray: each robot's boxes in its body frame
SIM_REALISM = "/sim/realism"    # latched std_msgs/String: the realism in effect, pulses applied
REALISM_SCALARS = ("ekf_position_noise", "ekf_attitude_noise", "ekf_velocity_noise",
                   "ekf_omega_noise", "ekf_position_bias", "ekf_attitude_bias", "actuation_noise",
                   "propulsion_lag", "bag_mass_told", "bag_stiffness_scale", "bag_damping_scale")
DISTURBANCE_PARAMS = ("time", "target", "force", "magnitude", "duration", "robot")
# the numbers of the per-tick messages that change (tick_wire templates), in wire order
_POSE_FIELDS = tick_wire.stamp_fields() + tick_wire.pose_fields("pose")
_TWIST_FIELDS = (tick_wire.stamp_fields() + tick_wire.vec_fields("twist.linear")
                 + tick_wire.vec_fields("twist.angular"))
_EKF_FIELDS = (tick_wire.stamp_fields() + tick_wire.pose_fields("pose")
               + tick_wire.vec_fields("velocity") + tick_wire.vec_fields("omega"))
_BAG_FIELDS = (tick_wire.stamp_fields() + tick_wire.pose_fields("pose") + tick_wire.vec_fields("velocity")
               + tick_wire.vec_fields("omega") + [("deformation", "d")])
_CONTACTS_FIELDS = tick_wire.stamp_fields() + [("robot_clearance", "d"), ("bag_clearance", "d")]
_CLOCK_FIELDS = tick_wire.stamp_fields("clock")


def _to_body(q: Any, v: list) -> tuple[float, float, float]:
    """A world vector in the body frame of q [x,y,z,w] (rotated by the conjugate)."""
    return qrot_floats((-q[0], -q[1], -q[2], q[3]), v)


class ParameterError(ValueError):
    """A sim_node parameter with a bad value; the message names the parameter."""


@dataclass(frozen=True)
class SimOptions:
    """sim_node's parameters, checked (see read_options)."""

    backend: str
    scenario: str
    overrides: dict
    seed: int
    clock_mode: str
    physics_rate: float
    publish_rate: float
    mesh_rate: float
    lockstep_timeout: float
    lockstep_start_timeout: float
    command_max_lead: float
    max_sim_time: float
    gui: bool
    drag: bool
    realism: str = ""                 # preset name; "" = the scenario's own
    realism_overrides: tuple = ()     # ((knob, value), ...) given as realism.<knob>
    disturbance: Disturbance | None = None   # one pulse given by realism.disturbance_*
    start_paused: bool = False        # paused until /sim/control RESUME; paused after a reset

    def realism_for(self, scenario: Scenario) -> Realism | None:
        """The realism the node forces on `scenario`, None when no realism parameter was given
        (each scenario then keeps its own). ScenarioError for a bad combination."""
        if not self.realism and not self.realism_overrides and self.disturbance is None:
            return None
        base = Realism.preset(self.realism) if self.realism else scenario.realism
        r = Realism.from_dict({**base.to_dict(), **dict(self.realism_overrides)})
        if self.disturbance is not None:
            r = Realism.from_dict({**r.to_dict(), "disturbances": [
                *r.to_dict()["disturbances"], self.disturbance.to_dict()]})
        return r


def _ranged(name: str, value: Any, lo: float, hi: float, lo_open: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"parameter {name} must be a number, got {value!r}") from None
    if not math.isfinite(v) or v > hi or v < lo or (lo_open and v == lo):
        rng = f"{'>' if lo_open else '>='} {lo:g} and <= {hi:g}"
        raise ParameterError(f"parameter {name} must be {rng}, got {value!r}")
    return v


def _choice(name: str, value: Any, known: tuple[str, ...]) -> str:
    v = str(value)
    if v not in known:
        raise ParameterError(f"parameter {name}: unknown value {v!r}; known: {', '.join(known)}")
    return v


def read_options(node: Any) -> SimOptions:
    """Declare and check every parameter (ParameterError names the first bad one)."""
    from roszen.parameters import read_only
    d = sim_defaults()

    def par(name: str, default: Any) -> Any:   # all read at start: `param set` is refused
        return node.declare_parameter(name, d.get(name, default), read_only()).value

    backend = _choice("backend", par("backend", "pybullet"), BACKENDS)
    scenario = str(par("scenario", "node2_to_jem"))
    try:
        scn.check_name(scenario)
    except ScenarioError as exc:
        raise ParameterError(f"parameter scenario: {exc}") from None
    bag_model = str(par("bag_model", "") or "")
    if bag_model:
        _choice("bag_model", bag_model, scn.BAG_MODELS + ("none",))
    bag_variant = str(par("bag_variant", "") or "")
    if bag_variant:
        _choice("bag_variant", bag_variant, scn.bag_variants())
    fem_solver = str(par("fem_solver", "") or "")
    if fem_solver:
        _choice("fem_solver", fem_solver, scn.FEM_SOLVERS)
    bag_resolution = par("bag_resolution", 0)             # FEM target nodes; 0: bags.yaml's
    if bag_resolution:
        bag_resolution = int(_ranged("bag_resolution", bag_resolution, *scn.RESOLUTION_RANGE))
    bag_mass = float(par("bag_mass", 0.0) or 0.0)
    if bag_mass:
        bag_mass = _ranged("bag_mass", bag_mass, *scn.MASS_RANGE)
    robots_param = str(par("robots", ""))       # comma list of robot names; "" = the scenario's
    robots = [r.strip() for r in robots_param.split(",")] if robots_param.strip() else None
    flight_mode = str(par("flight_mode", "") or "")
    if flight_mode:
        _choice("flight_mode", flight_mode, tuple(flight_modes.names()))
    clock_mode = _choice("clock_mode", par("clock_mode", "realtime"), CLOCK_MODES)
    physics_rate = _ranged("physics_rate", par("physics_rate", 350.0), 10.0, 10_000.0)
    publish_rate = _ranged("publish_rate", par("publish_rate", 62.5), 1.0, 1000.0)
    if physics_rate < publish_rate:
        raise ParameterError(f"parameter physics_rate ({physics_rate:g} Hz) must be >= "
                             f"publish_rate ({publish_rate:g} Hz)")
    mesh_rate = _ranged("mesh_rate", par("mesh_rate", 10.0), 0.01, 1000.0)
    lockstep_timeout = _ranged("lockstep_timeout", par("lockstep_timeout", 1.0), 0.0, 3600.0, True)
    lockstep_start_timeout = _ranged("lockstep_start_timeout", par("lockstep_start_timeout", 30.0),
                                     0.0, 3600.0, True)
    # commands stamped further than this ahead of sim time are dropped (stale, pre-reset)
    command_max_lead = _ranged("command_max_lead", par("command_max_lead", 0.5), 0.0, 3600.0, True)
    seed = par("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ParameterError(f"parameter seed must be a non-negative integer, got {seed!r}")
    max_sim_time = _ranged("max_sim_time", par("max_sim_time", 0.0), 0.0, 1e9)   # 0: no end
    gui = bool(par("gui", False))
    drag = bool(par("drag", False))
    realism, realism_overrides, disturbance = _read_realism(par)
    start_paused = par("start_paused", False)
    if not isinstance(start_paused, bool):
        raise ParameterError(f"parameter start_paused must be true or false, got {start_paused!r}")
    overrides = {"bag_model": bag_model or None, "bag_variant": bag_variant or None,
                 "bag_resolution": bag_resolution or None, "bag_mass": bag_mass or None,
                 "fem_solver": fem_solver or None, "robots": robots,
                 "flight_mode": flight_mode or None}
    return SimOptions(backend, scenario, overrides, int(seed), clock_mode, physics_rate,
                      publish_rate, mesh_rate, lockstep_timeout, lockstep_start_timeout,
                      command_max_lead, max_sim_time, gui, drag, realism, realism_overrides,
                      disturbance, start_paused=start_paused)


def _read_realism(par: Any) -> tuple[str, tuple, Disturbance | None]:
    """The realism parameters, each checked alone so the error names it."""
    preset = str(par("realism", "") or "").strip()
    try:
        if preset:
            Realism.preset(preset)
    except ScenarioError as exc:
        raise ParameterError(f"parameter realism: {exc}") from None
    overrides = []
    for knob in REALISM_SCALARS:
        value = par(f"realism.{knob}", None)          # None: not given (any type accepted)
        if value is None:
            continue
        try:
            Realism.from_dict({knob: value})
        except ScenarioError as exc:
            raise ParameterError(f"parameter realism.{knob}: {exc}") from None
        overrides.append((knob, float(value)))
    raw = {k: par(f"realism.disturbance_{k}", None) for k in DISTURBANCE_PARAMS}
    if isinstance(raw["force"], (list, tuple)) and len(raw["force"]) == 0:
        raw["force"] = None                             # an empty list: not given
    if raw["force"] is None and not raw["magnitude"]:
        given = [k for k, v in raw.items() if v not in (None, "")]
        if given:
            raise ParameterError(f"parameter realism.disturbance_{given[0]}: a disturbance needs "
                                 f"realism.disturbance_force [x, y, z] or realism.disturbance_magnitude")
        return preset, tuple(overrides), None
    d: dict[str, Any] = {k: v for k, v in raw.items() if v not in (None, "")}
    if "time" in d:
        try:
            if float(d["time"]) < 0:
                del d["time"]                          # drawn from the seed in 0..60 s
        except (TypeError, ValueError):
            raise ParameterError(f"parameter realism.disturbance_time must be a number (s), "
                                 f"got {d['time']!r}") from None
    try:
        dist = Disturbance.from_dict(d)
    except ScenarioError as exc:
        msg = str(exc)
        key = next((k for k in ("target", "duration", "time", "robot", "force", "magnitude")
                    if f" {k}" in msg), "force")
        raise ParameterError(f"parameter realism.disturbance_{key}: {msg}") from None
    return preset, tuple(overrides), dist


_CMD_HEAD = struct.Struct("<iiI")          # stamp sec, nanosec (read unsigned below), frame_id length
_CMD_WRENCH = struct.Struct("<6d")
_CMD_TAIL = 205     # bytes of a FamCommand from its wrench on (accel ... control_mode), CDR aligned


def decode_command(data: bytes) -> tuple[int, tuple] | None:
    """(stamp ns, body wrench) of a FamCommand in little-endian CDR, read at its fixed offsets
    (~1 us instead of ~10 us for the whole message), or None when the bytes are not that plain
    layout with a valid frame_id (the caller then decodes the whole message, which raises for
    malformed bytes as before)."""
    if len(data) < 16 + _CMD_TAIL or data[:4] != b"\x00\x01\x00\x00":
        return None
    sec, _, n = _CMD_HEAD.unpack_from(data, 4)
    end = 16 + n                                   # after the frame_id's bytes and its NUL
    off = 4 + ((end - 4 + 7) & ~7)                 # the wrench: 8-aligned after the 4-byte header
    if n < 1 or len(data) != off + _CMD_TAIL or data[end - 1] != 0:
        return None
    try:
        data[16:end - 1].decode()
    except UnicodeDecodeError:
        return None
    nsec = int.from_bytes(data[8:12], "little")
    return sec * 1_000_000_000 + nsec, _CMD_WRENCH.unpack_from(data, off)


def _short(text: str) -> str:
    return text if len(text) <= MAX_REPLY else text[:MAX_REPLY] + "..."


class SimNode:
    """Wires a SimBackend to topics and services; callbacks never raise."""

    def __init__(self, node: Any, backend: SimBackend, opts: SimOptions) -> None:
        import roszen
        from roszen import LATCHED

        self.roszen = roszen
        self.node = n = node
        self.log = n.get_logger()
        self.sim = backend
        self.opts = opts
        self.scenario = opts.scenario
        self.clock_mode = opts.clock_mode
        self.publish_rate = opts.publish_rate
        self.mesh_rate = opts.mesh_rate
        self.lockstep_timeout = opts.lockstep_timeout
        self.lockstep_start_timeout = opts.lockstep_start_timeout
        self.command_max_lead_ns = int(opts.command_max_lead * 1e9)
        self.max_sim_time = opts.max_sim_time
        self.names: list[str] = backend.robot_names()
        M = roszen.message_class
        self.M = {k: M(v) for k, v in {
            "clock": "rosgraph_msgs/msg/Clock", "pose": "geometry_msgs/msg/PoseStamped",
            "twist": "geometry_msgs/msg/TwistStamped", "ekf": "astrobee_msgs/msg/EkfState",
            "tf": "tf2_msgs/msg/TFMessage", "tfs": "geometry_msgs/msg/TransformStamped",
            "bag": "astrobee_msgs/msg/BagState", "mesh": "astrobee_msgs/msg/BagMesh",
            "contacts": "astrobee_msgs/msg/Contacts", "contact": "astrobee_msgs/msg/Contact",
            "markers": "visualization_msgs/msg/MarkerArray", "marker": "visualization_msgs/msg/Marker",
            "mode": "astrobee_msgs/msg/FlightMode", "fault": "astrobee_msgs/msg/Fault",
            "scenario": "astrobee_msgs/msg/ScenarioInfo", "pose_": "geometry_msgs/msg/Pose",
            "string": "std_msgs/msg/String"}.items()}
        self.pub_clock = n.create_publisher("rosgraph_msgs/msg/Clock", "/clock", roszen.CLOCK)
        self.pub_tf = n.create_publisher("tf2_msgs/msg/TFMessage", "/tf", 10)
        self.pub_bag = n.create_publisher("astrobee_msgs/msg/BagState", mc.BAG_STATE, 10)
        self.pub_mesh = n.create_publisher("astrobee_msgs/msg/BagMesh", mc.BAG_MESH, 2)
        self.pub_contacts = n.create_publisher("astrobee_msgs/msg/Contacts", mc.CONTACTS, 10)
        self.pub_markers = n.create_publisher("visualization_msgs/msg/MarkerArray", mc.MARKERS, LATCHED)
        self.pub_scenario = n.create_publisher("astrobee_msgs/msg/ScenarioInfo", mc.SIM_SCENARIO, LATCHED)
        self.pub_realism = n.create_publisher("std_msgs/msg/String", SIM_REALISM, LATCHED)
        # standard types any viewer shows (markers.py): the cargo bag's surface at the mesh
        # rate, the robot's URDF and boxes in its body frame (latched)
        self.pub_bag_marker = n.create_publisher("visualization_msgs/msg/Marker", BAG_MARKER, 2)
        self.pub_robot_description = n.create_publisher("std_msgs/msg/String",
                                                        "/robot_description", LATCHED)
        self.pub_robot_markers = n.create_publisher("visualization_msgs/msg/MarkerArray",
                                                    ROBOT_MARKERS, LATCHED)
        self.bag_surface = markers.BagSurface(M("visualization_msgs/msg/Marker"),
                                              M("geometry_msgs/msg/Point"))
        self._marker_cdr = roszen.codec.msg_support("visualization_msgs/msg/Marker").serialize
        self._realism_applied = -1      # pulses in the last /sim/realism
        self._command_support = roszen.codec.msg_support("astrobee_msgs/msg/FamCommand")
        self._templates: dict = {}      # per-tick message layouts -> tick_wire.Template | None
        self._noisy_for: tuple = (None, False)    # (scenario, its EKF is noisy)
        self._template_fields: dict = {}
        self._ekf_state = getattr(backend, "ekf_state", backend.robot_state)
        self.robot_io: dict[str, dict] = {}
        self._make_robot_io()
        n.create_service("astrobee_msgs/srv/Reset", mc.SIM_RESET, self._on_reset)
        n.create_service("astrobee_msgs/srv/SetFlightMode", "/sim/set_flight_mode",
                         lambda req: self._on_set_mode(req, None))
        n.create_service("astrobee_msgs/srv/SimControl", mc.SIM_CONTROL, self._on_control)
        self.start_paused = opts.start_paused
        self.paused = opts.start_paused
        self.pause_at_tick: int | None = None    # RESUME with steps: pause after this tick
        self._last_clock = -1e9                  # wall time of the last paused /clock
        self.pending_steps = 0
        self.tick = 0
        self._last_mesh = -1e9
        self._wall0 = time.monotonic()
        self._sim0 = 0.0
        self._warned: dict[str, float] = {}
        self.publish_markers()
        self.publish_scenario()
        self.publish_modes()
        if not self.start_paused:      # paused: the first state comes with the client's reset
            self.publish_state()
        self.publish_realism()
        bag = backend.scenario.bag
        self.log.info(f"sim up: scenario {backend.scenario.name}, robots {self.names}, "
                      f"bag {bag.model if bag else 'none'}, backend {opts.backend}, "
                      f"clock {self.clock_mode}, physics {1.0 / backend.dt:g} Hz")

    # ---- wiring per robot --------------------------------------------------------------
    def _make_robot_io(self) -> None:
        n, roszen = self.node, self.roszen
        for name in self.names:
            if name in self.robot_io:
                continue
            t = lambda rel, nm=name: mc.robot_topic(nm, rel)  # noqa: E731
            io = {
                "pose": n.create_publisher("geometry_msgs/msg/PoseStamped", t(mc.POSE), 10),
                "twist": n.create_publisher("geometry_msgs/msg/TwistStamped", t(mc.TWIST), 10),
                "ekf": n.create_publisher("astrobee_msgs/msg/EkfState", t(mc.EKF), 10),
                "mode": n.create_publisher("astrobee_msgs/msg/FlightMode", t(mc.FLIGHT_MODE),
                                           roszen.LATCHED),
                "fault": n.create_publisher("astrobee_msgs/msg/Fault", t(mc.FAULT), roszen.LATCHED),
                "cmd_stamp": -1, "raw_stamp": -1, "fault_state": None, "topic": t(mc.COMMAND),
            }
            n.create_subscription("astrobee_msgs/msg/FamCommand", t(mc.COMMAND),
                                  lambda data, nm=name: self._on_command_cdr(nm, data), 10,
                                  raw=True)
            n.create_service("astrobee_msgs/srv/SetFlightMode", t(mc.SET_FLIGHT_MODE),
                             lambda req, nm=name: self._on_set_mode(req, nm))
            self.robot_io[name] = io

    # ---- callbacks ---------------------------------------------------------------------
    def _warn(self, key: str, text: str, every: float = 2.0) -> None:
        now = time.monotonic()
        if now - self._warned.get(key, -1e9) >= every:
            self._warned[key] = now
            self.log.warn(text)

    def _on_command_cdr(self, name: str, data: bytes) -> None:
        """A FamCommand's CDR bytes: the stamp and wrench read in place when the layout is the
        plain one (little-endian, exact length), else the whole message decoded."""
        cmd = decode_command(data)
        if cmd is not None:
            self._command(name, *cmd)
            return
        try:
            msg = self._command_support.deserialize(data)
        except Exception as exc:  # noqa: BLE001 - as the subscription would: drop and say so
            self.log.error(f"dropped a sample on {self.robot_io[name]['topic']}: malformed CDR "
                           f"payload ({len(data)} bytes) for astrobee_msgs/msg/FamCommand: {exc}")
            return
        self._on_command(name, msg)

    def _on_command(self, name: str, msg: Any) -> None:
        try:
            w = msg.wrench
            wrench = [float(w.force.x), float(w.force.y), float(w.force.z), float(w.torque.x),
                      float(w.torque.y), float(w.torque.z)]
            stamp = mc.stamp_ns(msg.header.stamp)
        except (AttributeError, TypeError, ValueError) as exc:
            self._warn("badcmd", f"malformed command for robot {name!r} dropped: {exc}")
            return
        self._command(name, stamp, wrench)

    def _command(self, name: str, stamp: int, wrench: Any) -> None:
        """Hold a robot's commanded body wrench stamped `stamp` (ns), with the checks below."""
        if name not in self.names:
            return
        now = self.now_ns()
        if stamp > now + self.command_max_lead_ns:
            # after a reset sim time restarts at 0: a command answering a state from before the
            # reset carries a stamp ahead of the new sim time; it would also let lockstep skip
            # its waits up to that stamp
            self._warn("ahead", f"command for robot {name!r} stamped {stamp / 1e9:.3f} s, more than "
                       f"{self.command_max_lead_ns / 1e9:g} s ahead of sim time {now / 1e9:.3f} s "
                       f"(from before a reset?): dropped")
            return
        if not self.sim.command(wrench, name):
            self._warn("rejected", f"command rejected for robot {name!r} (non-finite or > 100 N/Nm): "
                       f"{np.array2string(np.asarray(wrench, float), precision=3)}")
            return
        io = self.robot_io[name]
        # a command never answers a tick the sim has not reached: lockstep counts it for the
        # current tick at most (a slightly-ahead stamp must not let later ticks run unanswered),
        # and a stamp answers one tick only (repeats of one command arriving a tick apart, as
        # on a loaded machine, must not each let the sim step on)
        if stamp != io["raw_stamp"]:
            io["raw_stamp"] = stamp
            io["cmd_stamp"] = max(io["cmd_stamp"], min(stamp, now))

    def _on_set_mode(self, req: Any, robot: str | None) -> Any:
        resp = self.roszen.response_class("astrobee_msgs/srv/SetFlightMode")()
        if robot is not None and robot not in self.names:
            resp.success, resp.message = False, f"robot {robot!r} is not in the current scenario"
            return resp
        try:
            self.sim.set_flight_mode(req.flight_mode, robot)
        except flight_modes.UnknownFlightMode as exc:
            resp.success, resp.message = False, _short(str(exc))
            return resp
        self.publish_modes()
        resp.success, resp.message = True, f"flight mode {req.flight_mode}"
        return resp

    def _on_reset(self, req: Any) -> Any:
        resp = self.roszen.response_class("astrobee_msgs/srv/Reset")()
        try:
            # the backend validates the whole request (name, file, seed) before it clears the
            # world: a refused reset leaves the running world as it was
            self.sim.reset(req.scenario or None, req.seed)
        except (ScenarioError, config.ConfigError, ValueError, TypeError) as exc:
            resp.success, resp.message = False, _short(f"reset refused: {exc}")
            self._warn("reset", resp.message, every=0.5)
            return resp
        self.names = self.sim.robot_names()
        self._make_robot_io()
        for io in self.robot_io.values():
            io["cmd_stamp"], io["raw_stamp"], io["fault_state"] = -1, -1, None
        self.tick = 0
        self._wall0, self._sim0 = time.monotonic(), 0.0
        if self.start_paused:          # deterministic runs: the client resumes when ready
            self.paused, self.pause_at_tick = True, None
        self.publish_markers()
        self.publish_scenario()
        self.publish_modes()
        self.publish_state()
        self.publish_realism()
        resp.success, resp.message = True, f"reset to {self.sim.scenario.name} (seed {self.sim.seed})"
        self.log.info(resp.message)
        return resp

    def _on_control(self, req: Any) -> Any:
        R = self.roszen.response_class("astrobee_msgs/srv/SimControl")
        resp = R()
        if req.command == mc.SimControl.PAUSE:
            self.paused, self.pause_at_tick = True, None
            resp.message = "paused"
        elif req.command == mc.SimControl.RESUME:
            steps = int(req.steps)
            if steps > MAX_CONTROL_STEPS:
                resp.success = False
                resp.message = f"steps {steps} > {MAX_CONTROL_STEPS}: ask for fewer per request"
                return resp
            self.paused = False
            self._wall0, self._sim0 = time.monotonic(), self.sim.time
            resp.message = "resumed"
            if steps > 0:              # run a budget of physics steps, then pause again
                self.pause_at_tick, t_pause = self._tick_after(steps)
                resp.success = True
                mc.set_stamp_ns(resp.sim_time, mc.to_ns(t_pause))
                resp.message = f"resumed until t={t_pause:.3f} s"
                return resp
            self.pause_at_tick = None
        elif req.command == mc.SimControl.STEP:
            if not self.paused:
                resp.success, resp.message = False, "STEP needs a paused simulation (send PAUSE first)"
                return resp
            steps = max(1, int(req.steps))
            if steps > MAX_CONTROL_STEPS:
                resp.success = False
                resp.message = f"steps {steps} > {MAX_CONTROL_STEPS}: ask for fewer per request"
                return resp
            self.sim.step(steps)
            self.publish_state()
            resp.message = f"stepped {steps}"
        else:
            resp.success, resp.message = False, f"unknown command {req.command} (0 PAUSE, 1 RESUME, 2 STEP)"
            return resp
        resp.success = True
        mc.set_stamp_ns(resp.sim_time, self.now_ns())
        return resp

    def _tick_after(self, steps: int) -> tuple[int, float]:
        """The first publish tick at which `steps` more physics steps are done, and the sim
        time then (summed step by step as the backend does, so equal to its stamp)."""
        k, n, t, dt = self.tick, self.sim.steps, self.sim.time, self.sim.dt
        goal = n + steps
        while n < goal:
            k += 1
            m = max(1, int(round(k / self.publish_rate / dt)) - n)
            n += m
            for _ in range(m):
                t += dt
        return k, t

    # ---- publishing --------------------------------------------------------------------
    def now_ns(self) -> int:
        return mc.to_ns(self.sim.time)

    def _robot_msgs(self, name: str) -> dict:
        """The per-tick messages of one robot, built once (publish() serialises at once, so
        mutating them afterwards is safe); headers, poses and rotations are shared objects."""
        M = self.M
        ps = M["pose"]()
        ps.header.frame_id = "world"
        tw = M["twist"]()
        tw.header = ps.header
        ekf = M["ekf"]()
        ekf.header = ps.header
        ekf.child_frame_id = f"{name}/body" if name else "body"
        ekf.pose = ps.pose
        ekf.confidence = mc.Confidence.GOOD
        ts = M["tfs"]()
        ts.header = ps.header
        ts.child_frame_id = ekf.child_frame_id
        ts.transform.rotation = ps.pose.orientation
        return {"pose": ps, "twist": tw, "ekf": ekf, "tfs": ts}

    def _global_msgs(self) -> dict:
        M = self.M
        bs = M["bag"]()
        bs.header.frame_id = "world"
        bts = M["tfs"]()
        bts.header = bs.header
        bts.child_frame_id = "bag"
        bts.transform.rotation = bs.pose.orientation
        cs = M["contacts"]()
        cs.header.frame_id = "world"
        return {"clock": M["clock"](), "tf": M["tf"](), "bag": bs, "bag_tfs": bts, "contacts": cs}

    def _send(self, pub: Any, key: Any, msg: Any, fields: Any, values: list) -> None:
        """Publish `msg` with `values` in its changing `fields` ((path, format) pairs, or a
        function making them): spliced into the layout's CDR template (tick_wire), or set on
        the object and serialised when the layout has no template."""
        tpl = self._templates.get(key, self)
        if tpl is self:                          # first time for this layout
            if callable(fields):
                fields = fields()
            tpl = self._templates[key] = tick_wire.Template.build(
                msg, self.roszen.codec.msg_support(pub.msg_type).serialize, fields)
            self._template_fields[key] = fields
        if tpl is not None:
            pub.publish(tpl.pack(values))
            return
        for (path, _), v in zip(self._template_fields[key], values):
            tick_wire.set_field(msg, path, v)
        pub.publish(msg)

    def publish_state(self) -> None:
        t = self.now_ns()
        sec, nsec = divmod(t, 1_000_000_000)
        g = self.__dict__.get("_msgs")
        if g is None:
            g = self._msgs = self._global_msgs()
        tw_ = tick_wire
        self._send(self.pub_clock, "clock", g["clock"], _CLOCK_FIELDS, [sec, nsec])
        tf_children: list = []
        tf_values: list = []
        positions = []
        sc = self.sim.scenario
        if sc is not self._noisy_for[0]:
            self._noisy_for = (sc, sc.realism.ekf_noisy)
        noisy = self._noisy_for[1]
        for name in self.names:
            io = self.robot_io[name]
            msgs = io.get("msgs")
            if msgs is None:
                msgs = io["msgs"] = self._robot_msgs(name)
            pos, q, v, w = self.sim.robot_state(name)
            positions.append(pos)
            p_, q_ = pos.tolist(), q.tolist()
            pose_values = [sec, nsec, *p_, *q_]
            self._send(io["pose"], ("pose", name), msgs["pose"], _POSE_FIELDS, pose_values)
            self._send(io["twist"], ("twist", name), msgs["twist"], _TWIST_FIELDS,
                       [sec, nsec, *v.tolist(), *w.tolist()])
            if noisy:                                # the estimate (the truth topics stay truth)
                pos_e, qe, v, w = self._ekf_state(name)
                ekf_pose = [*pos_e.tolist(), *qe.tolist()]
            else:
                qe, ekf_pose = q_, pose_values[2:]
            self._send(io["ekf"], ("ekf", name), msgs["ekf"], _EKF_FIELDS,
                       [sec, nsec, *ekf_pose, *v.tolist(), *_to_body(qe, w.tolist())])
            tf_children.append(msgs["tfs"])
            tf_values += pose_values
            fault = self.sim.faulted(name)
            if fault != io["fault_state"]:
                io["fault_state"] = fault
                f = self.M["fault"]()
                mc.set_stamp_ns(f.header.stamp, t)
                f.header.frame_id = "world"
                f.source = "sim/propulsion_watchdog"
                f.code = FAULT_WATCHDOG
                f.active = bool(fault)
                f.message = (f"no command for {self.sim.watchdog_timeout:g} s: propulsion stopped"
                             if fault else "commands flowing")
                io["fault"].publish(f)
        info = self.sim.bag_info()
        rc, bc = self.sim.clearance(positions)
        if info is not None:
            st = self.sim.bag_state()
            bs, bts = g["bag"], g["bag_tfs"]
            bs.model, bs.variant = info.model, info.variant
            bp, bq = st.position.tolist(), st.orientation.tolist()
            attached = [bool(a) for a in st.attached]
            if len(bs.attached) != len(attached):
                bs.attached = np.array(attached, dtype=bool)
            n = len(attached)
            self._send(self.pub_bag, ("bag", info.model, info.variant, n), bs,
                       lambda: _BAG_FIELDS + [(f"attached.{k}", "?") for k in range(n)],
                       [sec, nsec, *bp, *bq, *st.velocity.tolist(), *st.omega.tolist(),
                        float(st.deformation), *attached])
            tf_children.append(bts)
            tf_values += [sec, nsec, *bp, *bq]
            if self.sim.time - self._last_mesh >= 1.0 / self.mesh_rate - 1e-9:
                self._last_mesh = self.sim.time
                mc.set_stamp_ns(bs.header.stamp, t)
                pts = self.sim.bag_points()
                mm = self.M["mesh"]()
                mm.header = bs.header
                mm.num_nodes = len(pts)
                mm.positions = np.asarray(pts, np.float32).reshape(-1)
                self.pub_mesh.publish(mm)
                self.pub_bag_marker.publish(self.bag_surface.payload(        # CDR bytes
                    getattr(self.sim, "bag", None), pts, bs.header, self._marker_cdr))
        tf = g["tf"]
        key = ("tf", tuple(self.names), info is not None)
        if key not in self._templates:
            tf.transforms = tf_children
        self._send(self.pub_tf, key, tf, lambda: [
            f for i in range(len(tf_children)) for f in
            tw_.stamp_fields(f"transforms.{i}.header.stamp") +
            tw_.vec_fields(f"transforms.{i}.transform.translation") +
            [(f"transforms.{i}.transform.rotation.{a}", "d") for a in "xyzw"]], tf_values)
        cs = g["contacts"]
        contacts = self.sim.contacts()
        if not contacts:
            if cs.contacts:
                cs.contacts, cs.in_contact = [], False
            self._send(self.pub_contacts, "contacts", cs, _CONTACTS_FIELDS,
                       [sec, nsec, float(rc), float(bc)])
        else:
            lst = []
            for c in contacts:
                m = self.M["contact"]()
                m.body_a, m.body_b = c.body_a, c.body_b
                mc.set_vec(m.position, c.position)
                mc.set_vec(m.normal, c.normal)
                m.normal_force = float(c.normal_force)
                lst.append(m)
            cs.contacts = lst
            cs.in_contact = True
            mc.set_stamp_ns(cs.header.stamp, t)
            cs.robot_clearance, cs.bag_clearance = float(rc), float(bc)
            self.pub_contacts.publish(cs)
        effects = getattr(self.sim, "effects", None)
        if effects is not None and len(effects.log) != self._realism_applied:
            self.publish_realism()

    def publish_modes(self) -> None:
        for name in self.names:
            m, fm = self.M["mode"](), self.sim.flight_mode_of(name)
            mc.set_stamp_ns(m.header.stamp, self.now_ns())
            m.name, m.control_enabled, m.speed = fm.name, fm.control_enabled, fm.speed
            m.collision_radius = fm.collision_radius
            m.tolerance_pos = m.tolerance_pos_endpoint = fm.tolerance_pos
            m.tolerance_att = fm.tolerance_att
            for k in ("att_kp", "att_ki", "omega_kd", "pos_kp", "pos_ki", "vel_kd"):
                mc.set_vec(getattr(m, k), getattr(fm, k))
            m.hard_limit_vel, m.hard_limit_accel = fm.hard_limit_vel, fm.hard_limit_accel
            m.hard_limit_omega, m.hard_limit_alpha = fm.hard_limit_omega, fm.hard_limit_alpha
            self.robot_io[name]["mode"].publish(m)

    def publish_scenario(self) -> None:
        """Latched /sim/scenario: the scenario as built (overrides applied), for the controller
        and the mission (they read the bag and the goal from here, not from config files)."""
        sc: Scenario = self.sim.scenario
        m = self.M["scenario"]()
        mc.set_stamp_ns(m.header.stamp, self.now_ns())
        m.header.frame_id = "world"
        m.name, m.description = sc.name, sc.description
        m.seed = int(self.sim.seed)
        m.flight_mode = sc.flight_mode
        m.robots = [r.name for r in sc.robots]
        starts = []
        for r in sc.robots:
            ps = self.M["pose_"]()
            mc.set_pose(ps, r.position, r.orientation)
            starts.append(ps)
        m.starts = starts
        m.has_goal = sc.goal_position is not None
        if m.has_goal:
            mc.set_pose(m.goal, sc.goal_position, sc.goal_orientation)
        else:
            m.goal.orientation.w = 1.0
        m.face_forward = bool(sc.face_forward)
        m.carrying_bag = sc.bag is not None
        info = self.sim.bag_info()
        if sc.bag is not None:
            m.bag_model, m.bag_variant = sc.bag.model, sc.bag.variant
            m.bag_solver = sc.bag.solver if sc.bag.model == "fem" else ""
            told = getattr(self.sim, "told_bag_mass", None)
            m.bag_mass = float(told() if told is not None else sc.realism.told_mass(sc.bag.mass))
            m.bag_mass_true = float(sc.bag.mass)
            mc.set_vec(m.bag_size, sc.bag.size)
            m.bag_nodes = int(info.nodes) if info is not None else 0
        m.carry_extent = float(sc.carry_extent)
        m.realism = yaml.safe_dump(sc.realism.changed(), sort_keys=False)
        m.yaml = sc.to_yaml()
        self.pub_scenario.publish(m)

    def publish_realism(self) -> None:
        """Latched /sim/realism: the knobs in effect, the pulse schedule and the pulses applied
        (republished by publish_state when a pulse starts)."""
        sched = getattr(self.sim, "disturbance_schedule", None)
        applied = list(getattr(self.sim, "disturbance_log", []))
        m = self.M["string"]()
        m.data = yaml.safe_dump({"knobs": self.sim.scenario.realism.changed(),
                                 "schedule": sched() if sched is not None else [],
                                 "applied": applied}, sort_keys=False)
        self.pub_realism.publish(m)
        self._realism_applied = len(applied)

    def publish_markers(self) -> None:
        from .world import module_colour
        M = self.M
        arr = M["markers"]()
        out = []
        w = self.sim.world
        for i, (box, mod) in enumerate(zip(w.keep_in, w.modules)):
            m = M["marker"]()
            m.header.frame_id = "world"
            m.ns, m.id, m.type, m.action = "keep_in", i, 1, 0           # CUBE, ADD
            mc.set_vec(m.pose.position, (box[:3] + box[3:]) / 2)
            m.pose.orientation.w = 1.0
            mc.set_vec(m.scale, box[3:] - box[:3])
            m.color.r, m.color.g, m.color.b = module_colour(mod)
            m.color.a = 0.15
            out.append(m)
        for i, (name, mod) in enumerate(config.iss()["modules"].items()):
            m = M["marker"]()
            m.header.frame_id = "world"
            m.ns, m.id, m.type, m.action = "modules", i, 9, 0           # TEXT_VIEW_FACING
            mc.set_vec(m.pose.position, mod["origin"])
            m.pose.orientation.w = 1.0
            m.scale.z = 0.2
            m.color.r = m.color.g = m.color.b = m.color.a = 1.0
            m.text = mod.get("label", name)
            out.append(m)
        arr.markers = out
        self.pub_markers.publish(arr)
        robots = M["markers"]()             # robot boxes in each body frame (TF)
        robots.markers = [m for k, name in enumerate(self.names) for m in markers.robot_markers(
            M["marker"], f"{name}/body" if name else "body", 3 * k)]
        self.pub_robot_markers.publish(robots)
        desc = M["string"]()
        desc.data = markers.robot_description()
        self.pub_robot_description.publish(desc)

    # ---- main loop ---------------------------------------------------------------------
    def _drain(self, timeout: float = 0.0) -> None:
        """Run the callbacks that are ready (waiting up to `timeout` for the first)."""
        if self.node.spin_once(timeout_sec=timeout):
            while self.node.spin_once(timeout_sec=0):
                pass

    def _wait_commands(self) -> None:
        """Lockstep: wait for a command stamped >= the current tick from every commanded robot.

        A robot counts once its command topic has a publisher or it has sent a command. At the
        first tick (after start or a reset) the sim waits up to `lockstep_start_timeout` for a
        controller to appear, later ticks up to `lockstep_timeout`; on timeout it logs and
        steps on. While waiting it republishes the state every 0.5 s (a late subscriber may
        have missed it).
        """
        t = self.now_ns()
        first = self.tick == 0
        limit = self.lockstep_start_timeout if first else self.lockstep_timeout
        end = time.monotonic() + limit
        next_pub = time.monotonic() + 0.5

        def waiting():
            want = [n for n, io in self.robot_io.items() if n in self.names and
                    (io["cmd_stamp"] >= 0 or self.node.count_publishers(io["topic"]) > 0)]
            if first and not want:
                return ["(no controller yet)"]
            return [n or "/" for n in want if self.robot_io[n]["cmd_stamp"] < t]
        late = waiting()
        while late:
            now = time.monotonic()
            if now >= end:
                self._warn("lockstep", f"lockstep: no command for t={t / 1e9:.3f} s from {late} "
                           f"within {limit:g} s; stepping on")
                return
            if now >= next_pub and not self.start_paused:   # paused start: all were there
                self.publish_state()
                next_pub = now + 0.5
            self._drain(min(end - now, 0.02))
            late = waiting()

    def run_tick(self) -> None:
        """Wait (lockstep), step to the next publish tick, publish."""
        if self.clock_mode == "lockstep":
            self._wait_commands()
        if self.tick == 0:                  # the run (since start or the last reset) begins
            self._run_mark = (time.perf_counter(), time.process_time(), self.sim.time)
        self.tick += 1
        target = int(round(self.tick / self.publish_rate / self.sim.dt))
        self.sim.step(max(1, target - self.sim.steps))
        self.publish_state()

    def _rate(self) -> str:
        """': S sim s in W wall s (Rx real time), C CPU s (Px per CPU s)' since the run's first
        tick ('' before one); the CPU is this process's, its transport threads included."""
        mark = self.__dict__.get("_run_mark")
        if mark is None:
            return ""
        wall, cpu, sim = (time.perf_counter() - mark[0], time.process_time() - mark[1],
                          self.sim.time - mark[2])
        return (f": {sim:.3f} sim s in {wall:.3f} wall s ({sim / max(wall, 1e-9):.1f}x real time), "
                f"{cpu:.3f} CPU s ({sim / max(cpu, 1e-9):.1f}x per CPU s)")

    def spin(self) -> None:
        import roszen
        while roszen.ok() and self.node._alive:
            if self.max_sim_time and self.sim.time >= self.max_sim_time:
                self.log.info(f"max_sim_time {self.max_sim_time:g} s reached{self._rate()}")
                return
            self._drain(0.0)
            if self.paused:
                if self.start_paused and time.monotonic() - self._last_clock >= 1.0:
                    self._last_clock = time.monotonic()      # sim time for late nodes and
                    clk = self.M["clock"]()                   # the recorder (no state)
                    mc.set_stamp_ns(clk.clock, self.now_ns())
                    self.pub_clock.publish(clk)
                self._drain(0.05)
                continue
            self.run_tick()
            if self.pause_at_tick is not None and self.tick >= self.pause_at_tick:
                self.paused, self.pause_at_tick = True, None
            if self.clock_mode == "realtime":
                ahead = (self.sim.time - self._sim0) - (time.monotonic() - self._wall0)
                while ahead > 0:           # serve callbacks while waiting for the wall clock
                    self._drain(ahead)
                    ahead = (self.sim.time - self._sim0) - (time.monotonic() - self._wall0)
                if ahead < -1.0:        # far behind: do not try to catch up in a burst
                    self._warn("behind", f"sim running behind real time by {-ahead:.1f} s")
                    self._wall0, self._sim0 = time.monotonic(), self.sim.time

    def close(self) -> None:
        self.node.destroy_node()
        self.sim.close()


def build(argv: list[str]) -> SimNode:
    """The roszen node, its checked parameters, the backend they ask for, wired together.
    Raises ParameterError / ConfigError / ValueError (one line each) for a bad start."""
    import roszen
    node = roszen.Node("sim_node", argv=argv)
    backend = None
    try:
        opts = read_options(node)
        given = {k: v for k, v in opts.overrides.items() if v is not None}
        try:
            base = Scenario.load(opts.scenario)
        except ScenarioError as exc:
            raise ParameterError(f"parameter scenario: {exc}") from None
        sc = base.override(**given)      # its ScenarioError names the override (robots, ...)
        kw = dict(opts.overrides)
        try:
            realism = opts.realism_for(sc)
        except ScenarioError as exc:
            raise ParameterError(f"parameter realism: {exc}") from None
        if realism is not None:
            sc = sc.override(realism=realism)
            if opts.backend == "pybullet":
                kw["realism"] = realism          # kept over /sim/reset by name
        if sc.realism.physical and opts.backend != "pybullet":
            raise ParameterError(f"parameter realism: backend {opts.backend} models no realism "
                                 f"but bag_mass_told; use backend:=pybullet")
        backend = make_backend(opts.backend, sc, opts.seed, physics_rate=opts.physics_rate,
                               gui=opts.gui, drag=opts.drag, **kw)
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
    from roszen import node_main
    from roszen.parameters import ParameterException
    return node_main.run(build, argv, errors=(config.ConfigError, ValueError, ParameterException),
                         prog="sim_node")


if __name__ == "__main__":
    sys.exit(main())
