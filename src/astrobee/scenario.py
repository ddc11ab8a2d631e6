"""The typed scenario: loaded, validated and overridden once, then handed to every consumer.

A scenario (config/scenarios/NAME.yaml) says which robots start where, in which flight mode,
carrying which cargo bag, going where. The launcher validates it with its overrides before it
starts a process; the simulator builds it and publishes it (latched /sim/scenario) so the
controller and the mission read the bag and the goal from the graph, not from files of their
own. Names are restricted to the scenario folder (no paths, no '..').
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import yaml

from . import config, flight_modes
from . import rotations as rot
from .errors import ScenarioError
from .overrides import (BAG_MODELS, FEM_SOLVERS, MASS_RANGE, MAX_ROBOTS, NO_BAG,
                        OVERRIDE_KEYS, RESOLUTION_RANGE, Overrides, bag_variants,
                        default_grasp, grasp_names, parse_overrides)
from .overrides import NAME as _NAME
from .realism import Realism
from .realism import resolve as resolve_realism


def default_fem_solver() -> str:
    """The FEM solver a bag gets when none is named (config/bags.yaml models.fem.solver)."""
    return str(config.bags().get("models", {}).get("fem", {}).get("solver", "fast"))


def _vec(value: Any, n: int, what: str) -> tuple[float, ...]:
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ScenarioError(f"{what} must be {n} numbers, got {value!r}") from None
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise ScenarioError(f"{what} must be {n} finite numbers, got {value!r}")
    return tuple(float(x) for x in arr)


def _quat(value: Any, what: str) -> tuple[float, ...]:
    q = np.asarray(_vec(value, 4, what))
    n = float(np.linalg.norm(q))
    if n < 1e-6:
        raise ScenarioError(f"{what} must be a non-zero quaternion [x, y, z, w]")
    return tuple(float(x) for x in q / n)


@dataclass(frozen=True)
class RobotSpec:
    """One Astrobee: namespace name ('' = the default robot) and start pose."""

    name: str
    position: tuple[float, float, float]
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class BagSpec:
    """The cargo bag: model fidelity, handle variant, size (m), mass (kg), FEM resolution/solver."""

    model: str = "rigid"
    variant: str = "front"
    size: tuple[float, float, float] = (0.50, 0.42, 0.25)
    mass: float = 10.0
    resolution: int = 0            # FEM target node count; 0 = bags.yaml's
    solver: str = field(default_factory=default_fem_solver)   # FEM: fast (default) | bullet (reference)
    grasp: str = field(default_factory=default_grasp)         # strap (default) | hinge | clamp

    def validate(self) -> None:
        if self.model not in BAG_MODELS:
            raise ScenarioError(f"unknown bag model {self.model!r}; known: {', '.join(BAG_MODELS)}")
        if self.variant not in bag_variants():
            raise ScenarioError(f"unknown bag variant {self.variant!r}; known: "
                                f"{', '.join(bag_variants())}")
        if self.solver not in FEM_SOLVERS:
            raise ScenarioError(f"unknown fem solver {self.solver!r}; known: {', '.join(FEM_SOLVERS)}")
        if self.grasp not in grasp_names():
            raise ScenarioError(f"unknown grasp {self.grasp!r}; known: {', '.join(grasp_names())}")
        if not all(0.05 <= s <= 2.0 for s in self.size):
            raise ScenarioError(f"bag size must be 0.05..2 m per side, got {list(self.size)}")
        if not MASS_RANGE[0] <= self.mass <= MASS_RANGE[1]:
            raise ScenarioError(f"bag mass must be {MASS_RANGE[0]}..{MASS_RANGE[1]} kg, got {self.mass}")
        if self.resolution and not RESOLUTION_RANGE[0] <= self.resolution <= RESOLUTION_RANGE[1]:
            raise ScenarioError(f"bag resolution must be {RESOLUTION_RANGE[0]}..{RESOLUTION_RANGE[1]} "
                                f"nodes, got {self.resolution}")

    @property
    def handles(self) -> int:
        return len(config.bags()["handles"][self.variant])

    def as_dict(self) -> dict[str, Any]:
        d = {"model": self.model, "variant": self.variant, "size": list(self.size), "mass": self.mass}
        if self.resolution:
            d["resolution"] = self.resolution
        if self.model == "fem":
            d["solver"] = self.solver
        d["grasp"] = self.grasp
        return d


@dataclass(frozen=True)
class Scenario:
    """A validated scenario (see the module docstring)."""

    name: str
    description: str = ""
    flight_mode: str = "nominal"
    robots: tuple[RobotSpec, ...] = ()
    bag: BagSpec | None = None
    goal_position: tuple[float, float, float] | None = None
    goal_orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    face_forward: bool = False
    carry_extent_m: float | None = None     # planning margin for the carried bag (None: bags.yaml)
    initial_position_noise: float = 0.0
    realism: Realism = field(default_factory=Realism)   # astrobee.realism knobs (default off)
    extra: dict = field(default_factory=dict, compare=False)   # keys we do not interpret

    # ---- loading --------------------------------------------------------------------------
    @classmethod
    def load(cls, name: str, overrides: Overrides | None = None, /, **keys: Any) -> "Scenario":
        """config/scenarios/<name>.yaml, validated, with overrides applied (an Overrides or its
        keys as keywords, see override(); `realism=`: a preset name, a mapping of knobs or a
        Realism, replacing the file's)."""
        check_name(name)
        try:
            data = config.scenario(name)
        except config.ConfigError as exc:
            raise ScenarioError(str(exc)) from None
        return cls.from_dict(data, name).override(overrides, **keys)

    @classmethod
    def from_dict(cls, data: dict[str, Any], name: str = "custom") -> "Scenario":
        if not isinstance(data, dict):
            raise ScenarioError(f"scenario {name!r} must be a mapping")
        mode = data.get("flight_mode") or "nominal"
        try:
            flight_modes.get(mode)
        except flight_modes.UnknownFlightMode as exc:
            raise ScenarioError(str(exc)) from None
        raw_robots = data.get("robots")
        if raw_robots is None:
            raw_robots = [{"name": "", "position": config.waypoint("node_2").tolist()}]
        if not isinstance(raw_robots, list) or not raw_robots:
            raise ScenarioError(f"scenario {name!r}: robots must be a non-empty list, got {raw_robots!r}")
        if len(raw_robots) > MAX_ROBOTS:
            raise ScenarioError(f"scenario {name!r}: at most {MAX_ROBOTS} robots")
        robots = []
        for i, rc in enumerate(raw_robots):
            if not isinstance(rc, dict):
                raise ScenarioError(f"scenario {name!r}: robot {i} must be a mapping, got {rc!r}")
            rname = str(rc.get("name", "") or "")
            if rname and not _NAME.match(rname):
                raise ScenarioError(f"robot name {rname!r} is not a valid namespace")
            robots.append(RobotSpec(rname, _vec(rc.get("position"), 3, f"robot {i} position"),
                                    _quat(rc.get("orientation", [0, 0, 0, 1]), f"robot {i} orientation")))
        if len({r.name for r in robots}) != len(robots):
            raise ScenarioError(f"scenario {name!r}: robot names must differ")
        bag = None
        raw_bag = data.get("bag")
        if raw_bag:
            if not isinstance(raw_bag, dict):
                raise ScenarioError(f"scenario {name!r}: bag must be a mapping or null")
            default = config.bags()["default"]
            bag = BagSpec(str(raw_bag.get("model", default.get("model", "rigid"))),
                          str(raw_bag.get("variant", default.get("variant", "front"))),
                          _vec(raw_bag.get("size", default["size"]), 3, "bag size"),
                          float(raw_bag.get("mass", default["mass"])),
                          int(raw_bag.get("resolution", 0) or 0),
                          str(raw_bag.get("solver") or default_fem_solver()),
                          str(raw_bag.get("grasp") or default_grasp()))
            bag.validate()
            if bag.handles != len(robots) and bag.handles == 2 and len(robots) == 1:
                pass   # a two-handle bag held by one robot: the second handle hangs free
        goal = data.get("goal") or {}
        gp = _vec(goal["position"], 3, "goal position") if goal.get("position") is not None else None
        gq = _quat(goal.get("orientation", [0, 0, 0, 1]), "goal orientation")
        known = {"description", "flight_mode", "robots", "bag", "goal", "face_forward",
                 "carry_extent", "initial_position_noise", "name", "realism"}
        ce = data.get("carry_extent")
        noise = float(data.get("initial_position_noise", 0.0) or 0.0)
        if not 0 <= noise <= 0.5:
            raise ScenarioError(f"initial_position_noise must be 0..0.5 m, got {noise}")
        return cls(name=name, description=str(data.get("description", "")), flight_mode=mode,
                   robots=tuple(robots), bag=bag, goal_position=gp, goal_orientation=gq,
                   face_forward=bool(data.get("face_forward", False)),
                   carry_extent_m=None if ce is None else float(ce),
                   initial_position_noise=noise,
                   realism=resolve_realism(data.get("realism")),
                   extra={k: v for k, v in data.items() if k not in known})

    def override(self, overrides: Overrides | None = None, /, **keys: Any) -> "Scenario":
        """The scenario with overrides applied (an Overrides, or its keys as keywords:
        astrobee.overrides.OVERRIDE_KEYS; None/empty: keep), validated.

        bag_model 'none' removes the bag; a bag model given to a scenario without a bag adds the
        default bag (config/bags.yaml) with that model; bag keys without a bag are harmless.
        realism (a preset name, a mapping of knobs or a Realism; astrobee.realism) replaces the
        scenario's realism knobs. robots renames the robots (extra ones start 0.7 m apart)."""
        unknown = sorted(set(keys) - set(OVERRIDE_KEYS))
        if unknown or (overrides is not None and keys):
            raise TypeError(f"override() takes an Overrides or the keywords {OVERRIDE_KEYS}, "
                            f"got {unknown or sorted(keys)}")
        ov = overrides if overrides is not None else parse_overrides(keys)
        sc = self
        if ov.realism is not None:
            sc = replace(sc, realism=resolve_realism(ov.realism))
        if ov.flight_mode:
            sc = replace(sc, flight_mode=ov.flight_mode)
        bag = sc.bag
        if ov.bag_model == NO_BAG:
            bag = None
        elif ov.bag_model:
            if bag is None:
                d = config.bags()["default"]
                bag = BagSpec(variant=str(d.get("variant", "front")), size=_vec(d["size"], 3, "bag size"),
                              mass=float(d["mass"]))
            bag = replace(bag, model=ov.bag_model)
        if bag is not None:
            if ov.bag_variant:
                bag = replace(bag, variant=ov.bag_variant)
            if ov.bag_resolution:
                bag = replace(bag, resolution=ov.bag_resolution)
            if ov.bag_mass:
                bag = replace(bag, mass=ov.bag_mass)
            if ov.fem_solver:
                bag = replace(bag, solver=ov.fem_solver)
            if ov.grasp:
                bag = replace(bag, grasp=ov.grasp)
            bag.validate()
        sc = replace(sc, bag=bag)
        if ov.robots:
            base = sc.robots[0]
            specs = [replace(sc.robots[i], name=n) if i < len(sc.robots) else
                     RobotSpec(n, tuple(float(x) for x in np.add(base.position, [0.7 * i, 0, 0])),
                               base.orientation)
                     for i, n in enumerate(ov.robots)]
            sc = replace(sc, robots=tuple(specs))
        return sc

    def with_start_goal(self, start: tuple | None = None, goal: tuple | None = None) -> "Scenario":
        """The scenario with its (first) robot's start pose and/or its goal pose replaced
        ((position, orientation) pairs; the orientation normalised)."""
        sc = self
        if start is not None:
            r0 = replace(sc.robots[0], position=tuple(float(x) for x in start[0]),
                         orientation=tuple(float(x) for x in rot.normalize(np.asarray(start[1], float))))
            sc = replace(sc, robots=(r0, *sc.robots[1:]))
        if goal is not None:
            sc = replace(sc, goal_position=tuple(float(x) for x in goal[0]),
                         goal_orientation=tuple(float(x) for x in rot.normalize(np.asarray(goal[1], float))))
        return sc

    # ---- facts ----------------------------------------------------------------------------
    @property
    def carrying_bag(self) -> bool:
        return self.bag is not None

    @property
    def carry_extent(self) -> float:
        """Extra planning clearance for the carried bag (m): the scenario's, else bags.yaml's."""
        if self.bag is None:
            return 0.0
        if self.carry_extent_m is not None:
            return float(self.carry_extent_m)
        return float(config.bags().get("carry_extent", 0.0))

    @property
    def robot_names(self) -> list[str]:
        return [r.name for r in self.robots]

    def as_dict(self) -> dict[str, Any]:
        """The scenario as YAML-able data (what /sim/scenario carries in full)."""
        d: dict[str, Any] = dict(self.extra)
        d.update({"name": self.name, "description": self.description,
                  "flight_mode": self.flight_mode,
                  "robots": [{"name": r.name, "position": list(r.position),
                              "orientation": list(r.orientation)} for r in self.robots],
                  "bag": None if self.bag is None else self.bag.as_dict(),
                  "face_forward": self.face_forward,
                  "initial_position_noise": self.initial_position_noise})
        if self.goal_position is not None:
            d["goal"] = {"position": list(self.goal_position),
                         "orientation": list(self.goal_orientation)}
        if self.carry_extent_m is not None:
            d["carry_extent"] = self.carry_extent_m
        if self.realism.enabled:
            d["realism"] = self.realism.changed()
        return d

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.as_dict(), sort_keys=False)


def check_name(name: str) -> str:
    """A scenario name: letters, digits, '_' and '-' only (no paths: the folder is fixed)."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise ScenarioError(f"scenario name must be letters, digits, '_' or '-' (a file of "
                            f"config/scenarios/), got {name!r}")
    return name


def known() -> list[str]:
    """Names of the scenarios in config/scenarios/."""
    return sorted(p.stem for p in (config.config_dir() / "scenarios").glob("*.yaml"))
