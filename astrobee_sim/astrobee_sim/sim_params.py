"""sim_node's parameters: each declared read-only and checked at start, so a bad one ends the node
with one line naming it (ParameterError), and the checked set as one frozen SimOptions.

The realism parameters are `realism` (a preset of config/realism.yaml), `realism.<knob>` for
every scalar field of astrobee.realism.Realism (REALISM_SCALARS, derived from the dataclass so a
new knob is a parameter with no edit here) and one disturbance (`realism.disturbance_*`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

from astrobee import flight_modes
from astrobee import scenario as scn
from astrobee.realism import Disturbance, Realism
from astrobee.scenario import Scenario, ScenarioError

from .backend import BACKENDS, sim_defaults

CLOCK_MODES = ("realtime", "fast", "lockstep")
# the scalar realism knobs, each a `realism.<knob>` parameter: Realism's float fields
REALISM_SCALARS = tuple(f.name for f in fields(Realism) if f.type in ("float", float))
DISTURBANCE_PARAMS = ("time", "target", "force", "magnitude", "duration", "robot")


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
