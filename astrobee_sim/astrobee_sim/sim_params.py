"""sim_node's parameters: each declared read-only with its range, choices or validator, so a bad
one ends the node at start with one line naming it (the node's ParameterException, or
ParameterError for a check across parameters), and the checked set as one frozen SimOptions.

The scenario override parameters are astrobee.overrides' keys (OVERRIDE_KEYS but realism, which
sim_node takes apart, below), checked by its one parser.

The realism parameters are `realism` (a preset of config/realism.yaml), `realism.<knob>` for
every scalar field of astrobee.realism.Realism (REALISM_SCALARS, derived from the dataclass so a
new knob is a parameter with no edit here) and one disturbance (`realism.disturbance_*`).
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from astrobee import scenario as scn
from astrobee.overrides import OVERRIDE_KEYS, Overrides, parse_overrides
from astrobee.realism import Disturbance, Realism
from astrobee.scenario import Scenario, ScenarioError

from .backend import BACKENDS
from .world import sim_defaults

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
    overrides: Overrides               # the scenario overrides given (realism apart, below)
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


def _positive(value: Any) -> None:
    """A validator: > 0 (the range's upper end is the descriptor's)."""
    if value <= 0:
        raise ValueError(f"must be > 0, got {value!r}")


def _override_default(key: str) -> Any:
    """The ROS parameter default ('not given') of an override key, by its Overrides type."""
    kind = next(f.type for f in fields(Overrides) if f.name == key)
    kind = kind if isinstance(kind, str) else str(kind)
    return 0 if kind.startswith("int") else 0.0 if kind.startswith("float") else ""


def _override_check(key: str) -> Any:
    """A validator: the one override parser on this key's value (astrobee.overrides); its
    message without the key, which the node's refusal names."""
    def check(value: Any) -> None:
        try:
            parse_overrides({key: value}, source="parameters")
        except ScenarioError as exc:
            text = str(exc)
            raise ValueError(text[len(key):].lstrip(": ") if text.startswith(key) else text) from None
    return check


def read_options(node: Any) -> SimOptions:
    """Declare every parameter read-only with its range, choices or validator (the node's
    declare refuses a bad start value with one line naming it), then the cross-checks by hand
    (ParameterError names the parameter)."""
    from roszen.parameters import read_only
    d = sim_defaults()

    def par(name: str, default: Any, **check: Any) -> Any:   # read at start: `param set` is refused
        return node.declare_parameter(name, d.get(name, default), read_only(**check)).value

    backend = par("backend", "pybullet", choices=BACKENDS)
    scenario = str(par("scenario", "node2_to_jem"))
    try:
        scn.check_name(scenario)
    except ScenarioError as exc:
        raise ParameterError(f"parameter scenario: {exc}") from None
    overrides = parse_overrides({key: par(key, _override_default(key), validator=_override_check(key))
                                 for key in OVERRIDE_KEYS if key != "realism"}, source="parameters")
    clock_mode = par("clock_mode", "realtime", choices=CLOCK_MODES)
    physics_rate = par("physics_rate", 350.0, min_value=10.0, max_value=10_000.0)
    publish_rate = par("publish_rate", 62.5, min_value=1.0, max_value=1000.0)
    if physics_rate < publish_rate:
        raise ParameterError(f"parameter physics_rate ({physics_rate:g} Hz) must be >= "
                             f"publish_rate ({publish_rate:g} Hz)")
    mesh_rate = par("mesh_rate", 10.0, min_value=0.01, max_value=1000.0)
    lockstep_timeout = par("lockstep_timeout", 1.0, max_value=3600.0, validator=_positive)
    lockstep_start_timeout = par("lockstep_start_timeout", 30.0, max_value=3600.0,
                                 validator=_positive)
    # commands stamped further than this ahead of sim time are dropped (stale, pre-reset)
    command_max_lead = par("command_max_lead", 0.5, max_value=3600.0, validator=_positive)
    seed = par("seed", 0, min_value=0)
    max_sim_time = par("max_sim_time", 0.0, min_value=0.0, max_value=1e9)   # 0: no end
    gui = bool(par("gui", False))
    drag = bool(par("drag", False))
    realism, realism_overrides, disturbance = _read_realism(par)
    start_paused = bool(par("start_paused", False))
    return SimOptions(backend, scenario, overrides, int(seed), clock_mode, float(physics_rate),
                      float(publish_rate), float(mesh_rate), float(lockstep_timeout),
                      float(lockstep_start_timeout), float(command_max_lead), float(max_sim_time),
                      gui, drag, realism, realism_overrides, disturbance, start_paused=start_paused)


def _preset(name: Any) -> None:
    """A validator: '' or a preset of config/realism.yaml."""
    if str(name).strip():
        Realism.preset(str(name).strip())


def _read_realism(par: Any) -> tuple[str, tuple, Disturbance | None]:
    """The realism parameters, each checked alone so the error names it."""
    preset = str(par("realism", "", validator=_preset) or "").strip()
    overrides = []
    for knob in REALISM_SCALARS:      # None: not given (any type accepted, then checked)
        value = par(f"realism.{knob}", None, validator=lambda v, k=knob: Realism.from_dict({k: v}))
        if value is not None:
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
