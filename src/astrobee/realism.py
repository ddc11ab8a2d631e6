"""Realism knobs of the simulator: localization noise, actuation noise and lag, crew bumps, a
wrong bag mass told to the controller and a softer or stiffer bag. All off by default.

Transport-free and physics-free: this module only holds and validates the knobs (a frozen
`Realism`, loaded from a scenario's `realism:` section, a preset of config/realism.yaml, a
mapping or sim_node parameters); astrobee_sim.realism_effects applies them to a simulation.
Bad values raise `astrobee.errors.ScenarioError` (also astrobee.scenario's) with a one-line
message naming the knob.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

from . import config
from .errors import ScenarioError

TARGETS = ("robot", "bag")
PRESETS_FILE = "realism.yaml"
MAX_NOISE = {"ekf_position_noise": 1.0, "ekf_attitude_noise": 1.0, "ekf_velocity_noise": 1.0,
             "ekf_omega_noise": 1.0, "ekf_position_bias": 1.0, "ekf_attitude_bias": 1.0,
             "actuation_noise": 2.0, "propulsion_lag": 10.0}
SCALE_RANGE = (0.0, 100.0)           # bag_mass_told, bag/handle stiffness scales, bag_damping_scale
MAX_FORCE = 100.0                    # N, a disturbance pulse
MAX_DURATION = 60.0                  # s, a disturbance pulse
MAX_TIME = 1e6                       # s


def _fail(message: str) -> None:
    raise ScenarioError(message)


def _number(name: str, value: Any, lo: float, hi: float, lo_open: bool = False) -> float:
    if isinstance(value, bool):
        _fail(f"realism {name} must be a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        _fail(f"realism {name} must be a number, got {value!r}")
    if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo):
        _fail(f"realism {name} must be {'>' if lo_open else '>='} {lo:g} and <= {hi:g}, got {value!r}")
    return v


@dataclass(frozen=True)
class Disturbance:
    """A force pulse (a crew bump) on a robot or on the bag, world frame.

    time: start (s of sim time), or None to draw it uniformly from the seed in [t_min, t_max];
    force: the world-frame force (N), or None to push with `magnitude` N along a direction drawn
    from the seed; duration: s; robot: which robot ("" the default one; for target "robot")."""

    time: float | None = None
    target: str = "robot"
    force: tuple[float, float, float] | None = None
    magnitude: float = 0.0
    duration: float = 0.1
    robot: str = ""
    t_min: float = 0.0
    t_max: float = 60.0

    @classmethod
    def from_dict(cls, d: Any, index: int = 0) -> "Disturbance":
        what = f"disturbance {index}"
        if not isinstance(d, dict):
            _fail(f"realism {what} must be a mapping, got {d!r}")
        known = {f.name for f in fields(cls)}
        extra = sorted(set(d) - known)
        if extra:
            _fail(f"realism {what}: unknown key {extra[0]!r}; known: {', '.join(sorted(known))}")
        target = str(d.get("target", "robot"))
        if target not in TARGETS:
            _fail(f"realism {what}: target must be one of {', '.join(TARGETS)}, got {target!r}")
        t = d.get("time")
        t = None if t is None else _number(f"{what} time", t, 0.0, MAX_TIME)
        t_min = _number(f"{what} t_min", d.get("t_min", 0.0), 0.0, MAX_TIME)
        t_max = _number(f"{what} t_max", d.get("t_max", 60.0), 0.0, MAX_TIME)
        if t_max < t_min:
            _fail(f"realism {what}: t_max ({t_max:g}) must be >= t_min ({t_min:g})")
        force = d.get("force")
        if force is not None:
            try:
                vals = [float(x) for x in force]
            except (TypeError, ValueError):
                _fail(f"realism {what} force must be 3 numbers [x, y, z] (N), got {force!r}")
            if len(vals) != 3 or not all(math.isfinite(x) and abs(x) <= MAX_FORCE for x in vals):
                _fail(f"realism {what} force must be 3 finite numbers within +-{MAX_FORCE:g} N, "
                      f"got {force!r}")
            force = tuple(vals)
        magnitude = _number(f"{what} magnitude", d.get("magnitude", 0.0), 0.0, MAX_FORCE)
        if force is None and magnitude == 0.0:
            _fail(f"realism {what} needs a force [x, y, z] or a magnitude > 0")
        if force is not None and magnitude:
            _fail(f"realism {what}: give a force or a magnitude, not both")
        duration = _number(f"{what} duration", d.get("duration", 0.1), 0.0, MAX_DURATION, lo_open=True)
        robot = d.get("robot", "") or ""
        if not isinstance(robot, str):
            _fail(f"realism {what} robot must be a robot name, got {robot!r}")
        return cls(t, target, force, magnitude, duration, robot, t_min, t_max)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"time": self.time, "target": self.target, "duration": self.duration}
        if self.force is not None:
            d["force"] = list(self.force)
        else:
            d["magnitude"] = self.magnitude
        if self.robot:
            d["robot"] = self.robot
        if self.time is None:
            d["t_min"], d["t_max"] = self.t_min, self.t_max
        return d


@dataclass(frozen=True)
class Realism:
    """The realism knobs (all off by default: truth state, exact actuation, the true mass).

    EKF (on /gnc/ekf and Simulation.ekf_state; truth topics stay truth):
      ekf_position_noise m, ekf_attitude_noise rad, ekf_velocity_noise m/s, ekf_omega_noise
      rad/s: white noise std per sample (per axis; attitude as a small rotation vector);
      ekf_position_bias m, ekf_attitude_bias rad: std of a constant per-run bias drawn from the
      seed (per robot).
    Actuation: actuation_noise, a multiplicative std on each commanded force/torque axis (drawn
      each 16 ms control period); propulsion_lag s, the time constant of a first-order lag
      between the held command and the applied wrench (still clipped to the flight mode).
    disturbances: force pulses (Disturbance), e.g. a crew bump.
    Bag: bag_mass_told scales the bag mass the controller is told (/sim/scenario bag_mass):
      1 the truth, 0 no bag mass at all. bag_stiffness_scale / bag_damping_scale scale the bag
      model as built: fem (both solvers) elastic_stiffness / damping of the mass-spring mesh;
      constraint the handle constraints' max_force (stiffness; no damping to scale); composite
      the block ties' max_force (stiffness; no damping); rigid nothing (a rigid box).
      handle_stiffness_scale scales the grasp's stiffnesses (astrobee_sim.grasp: the strap's
      hold and twist spring, the hinge's and the clamp's holds; config/bags.yaml grasp).
    """

    ekf_position_noise: float = 0.0
    ekf_attitude_noise: float = 0.0
    ekf_velocity_noise: float = 0.0
    ekf_omega_noise: float = 0.0
    ekf_position_bias: float = 0.0
    ekf_attitude_bias: float = 0.0
    actuation_noise: float = 0.0
    propulsion_lag: float = 0.0
    disturbances: tuple[Disturbance, ...] = ()
    bag_mass_told: float = 1.0
    bag_stiffness_scale: float = 1.0
    bag_damping_scale: float = 1.0
    handle_stiffness_scale: float = 1.0

    # ---- what is on ---------------------------------------------------------------------
    @property
    def ekf_noisy(self) -> bool:
        """Any localization noise or bias (ekf_state differs from the truth)."""
        return any((self.ekf_position_noise, self.ekf_attitude_noise, self.ekf_velocity_noise,
                    self.ekf_omega_noise, self.ekf_position_bias, self.ekf_attitude_bias))

    @property
    def affects_stepping(self) -> bool:
        """Actuation noise, lag or disturbances: the physics step loop has work to do."""
        return bool(self.actuation_noise or self.propulsion_lag or self.disturbances)

    @property
    def physical(self) -> bool:
        """Any knob the simulator's physics or EKF has to model (all but bag_mass_told)."""
        return (self.ekf_noisy or self.affects_stepping or self.bag_stiffness_scale != 1.0
                or self.bag_damping_scale != 1.0 or self.handle_stiffness_scale != 1.0)

    @property
    def enabled(self) -> bool:
        """Any knob away from its default."""
        return self.physical or self.bag_mass_told != 1.0

    def told_mass(self, true_mass: float) -> float:
        """The bag mass the controller is told for a bag of `true_mass` kg."""
        return float(true_mass) * self.bag_mass_told

    # ---- loading ------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, d: Any) -> "Realism":
        """A mapping of knobs (missing ones at their defaults), optionally with `preset: NAME`
        as the base the other keys override. ScenarioError (one line) for anything bad."""
        if d is None:
            return cls()
        if not isinstance(d, dict):
            _fail(f"realism must be a preset name or a mapping of knobs, got {d!r}")
        d = dict(d)
        base = cls.preset(str(d.pop("preset"))) if "preset" in d else cls()
        known = {f.name for f in fields(cls)}
        extra = sorted(set(d) - known)
        if extra:
            _fail(f"unknown realism knob {extra[0]!r}; known: preset, {', '.join(sorted(known))}")
        values: dict[str, Any] = {}
        for name, hi in MAX_NOISE.items():
            if name in d:
                values[name] = _number(name, d[name], 0.0, hi)
        for name in ("bag_mass_told", "bag_stiffness_scale", "bag_damping_scale",
                     "handle_stiffness_scale"):
            if name in d:
                values[name] = _number(name, d[name], *SCALE_RANGE,
                                       lo_open=name != "bag_mass_told")
        if "disturbances" in d:
            raw = d["disturbances"] or []
            if isinstance(raw, dict):
                raw = [raw]
            if not isinstance(raw, (list, tuple)):
                _fail(f"realism disturbances must be a list of mappings, got {raw!r}")
            values["disturbances"] = tuple(Disturbance.from_dict(x, i) for i, x in enumerate(raw))
        return replace(base, **values)

    @classmethod
    def preset(cls, name: str) -> "Realism":
        """A preset of config/realism.yaml (off, astrobee, harsh, ...)."""
        presets = preset_table()
        if name not in presets:
            _fail(f"unknown realism preset {name!r}; known: {', '.join(presets)}")
        body = presets[name] or {}
        if not isinstance(body, dict) or "preset" in body:
            _fail(f"realism preset {name!r} in config/{PRESETS_FILE} must be a mapping of knobs")
        return cls.from_dict(body)

    def to_dict(self) -> dict[str, Any]:
        """Every knob as YAML-able data (from_dict(to_dict()) == self)."""
        d: dict[str, Any] = {f.name: getattr(self, f.name) for f in fields(self)
                             if f.name != "disturbances"}
        d["disturbances"] = [x.to_dict() for x in self.disturbances]
        return d

    def changed(self) -> dict[str, Any]:
        """Only the knobs away from their defaults (what a summary needs to say)."""
        off = Realism().to_dict()
        return {k: v for k, v in self.to_dict().items() if v != off[k]}


def preset_table() -> dict[str, Any]:
    """config/realism.yaml's presets (name -> mapping of knobs)."""
    try:
        data = config.load_yaml(PRESETS_FILE)
    except config.ConfigError as exc:
        _fail(str(exc))
    presets = data.get("presets")
    if not isinstance(presets, dict):
        _fail(f"config/{PRESETS_FILE} needs a `presets:` mapping")
    return {str(k): v for k, v in presets.items()}


def presets() -> list[str]:
    """Names of the presets."""
    return list(preset_table())


def resolve(value: Any) -> Realism:
    """A Realism from what a user may give: None (off), a Realism, a preset name, or a mapping
    (knobs, optionally with `preset:`). ScenarioError for anything else or a bad knob."""
    if value is None:
        return Realism()
    if isinstance(value, Realism):
        return value
    if isinstance(value, str):
        return Realism.preset(value.strip() or "off")
    if isinstance(value, dict):
        return Realism.from_dict(value)
    _fail(f"realism must be a preset name, a mapping or a Realism, got {type(value).__name__}")
    raise AssertionError   # unreachable (for type checkers)
