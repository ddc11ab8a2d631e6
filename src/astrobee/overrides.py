"""The scenario override keys and the one parser of their values (one owner of both).

A scenario (astrobee.scenario) is overridden by a few keys, whoever gives them: launch
arguments (`bag_mass:=12`, strings), ROS parameters of sim_node (typed), study keys (YAML
values) or Python keywords (Flight, Simulation, the Gymnasium environments):

    OVERRIDE_KEYS = bag_model, bag_variant, bag_resolution, bag_mass, fem_solver,
                    flight_mode, robots, realism, grasp

    ov = parse_overrides({"bag_mass": "12", "robots": "a,b"}, source="launch")
    ov.given()                  # {'bag_mass': 12.0, 'robots': ('a', 'b')}: keywords of Scenario.override
    ov.apply(scenario)          # the scenario with them applied (validated)
    ov.as_parameters()          # sim_node's parameter values (robots comma-joined)

Only the keys of OVERRIDE_KEYS are read from the mapping (the caller's other keys are its
own). "Not given" is None in any source, '' for strings, 0 for bag_resolution / bag_mass
(the ROS parameter defaults). A bad value raises ScenarioError with one line naming the key.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, fields
from typing import Any, Mapping

from . import config, flight_modes
from .errors import ScenarioError
from .realism import Realism, resolve as resolve_realism

BAG_MODELS = ("fem", "constraint", "composite", "rigid")
NO_BAG = "none"                        # bag_model override removing the bag
FEM_SOLVERS = ("bullet", "fast")
RESOLUTION_RANGE = (27, 5000)          # FEM target node count accepted
MASS_RANGE = (0.05, 100.0)             # kg
MAX_ROBOTS = 4
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_\-]{0,63}$")   # scenario and robot names
SOURCES = ("python", "launch", "parameters", "study")


def bag_variants() -> tuple[str, ...]:
    """The cargo bag variants of config/bags.yaml (its handle layouts)."""
    return tuple(config.bags()["handles"])


def grasp_names() -> tuple[str, ...]:
    """The grasp models of config/bags.yaml (grasp.models; astrobee_sim.grasp implements them)."""
    return tuple((config.bags().get("grasp") or {}).get("models") or ("strap", "hinge", "clamp"))


def default_grasp() -> str:
    """The grasp a bag gets when none is named (config/bags.yaml grasp.default)."""
    return str((config.bags().get("grasp") or {}).get("default", "strap"))


@dataclass(frozen=True)
class Overrides:
    """Validated scenario overrides (None: keep the scenario's). realism is a preset name or a
    Realism (a mapping of knobs resolved)."""

    bag_model: str | None = None
    bag_variant: str | None = None
    bag_resolution: int | None = None
    bag_mass: float | None = None
    fem_solver: str | None = None
    flight_mode: str | None = None
    robots: tuple[str, ...] | None = None
    realism: str | Realism | None = None
    grasp: str | None = None

    def given(self) -> dict[str, Any]:
        """The overrides set, as keywords of Scenario.override."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if getattr(self, f.name) is not None}

    def apply(self, scenario: Any) -> Any:
        """The Scenario with these overrides applied (the same object when none is set)."""
        given = self.given()
        return scenario.override(**given) if given else scenario

    def as_parameters(self) -> dict[str, Any]:
        """sim_node's parameter values for the overrides set (robots comma-joined; a realism
        given as a mapping has no parameter form and raises ScenarioError)."""
        out = self.given()
        if "robots" in out:
            out["robots"] = ",".join(out["robots"])
        if isinstance(out.get("realism"), Realism):
            raise ScenarioError("realism: only a preset name can be a parameter")
        return out


OVERRIDE_KEYS: tuple[str, ...] = tuple(f.name for f in fields(Overrides))


def _absent(value: Any) -> bool:
    return value is None or (isinstance(value, str) and not value.strip())


def _choice(key: str, value: Any, known: tuple[str, ...] | list[str]) -> str:
    v = str(value).strip() if isinstance(value, str) else value
    if not isinstance(v, str) or v not in known:
        raise ScenarioError(f"{key}: unknown value {value!r}; known: {', '.join(known)}")
    return v


def _number(key: str, value: Any, kind: type, lo: float, hi: float, unit: str) -> Any:
    if isinstance(value, bool):
        raise ScenarioError(f"{key} must be a number, got {value!r}")
    try:
        v = kind(value.strip() if isinstance(value, str) else value)
    except (TypeError, ValueError):
        raise ScenarioError(f"{key} must be {'an integer' if kind is int else 'a number'}, "
                            f"got {value!r}") from None
    if kind is int and isinstance(value, float) and value != v:
        raise ScenarioError(f"{key} must be an integer, got {value!r}")
    if v == 0:
        return None                    # 0: not given (the parameter's default)
    if not (math.isfinite(v) and lo <= v <= hi):
        raise ScenarioError(f"{key} must be {lo:g}..{hi:g} {unit}, got {value!r}")
    return v


def _robots(value: Any) -> tuple[str, ...]:
    names = value.split(",") if isinstance(value, str) else value
    if not isinstance(names, (list, tuple)):
        raise ScenarioError(f"robots must be a comma-separated list of names, got {value!r}")
    out = tuple(str(n).strip() for n in names)
    if not 1 <= len(out) <= MAX_ROBOTS or len(set(out)) != len(out):
        raise ScenarioError(f"robots must be 1..{MAX_ROBOTS} distinct names, got {list(out)}")
    for n in out:
        if n and not NAME.match(n):
            raise ScenarioError(f"robot name {n!r} is not a valid namespace")
    return out


def _realism(value: Any, source: str) -> str | Realism:
    if source in ("launch", "parameters") and not isinstance(value, str):
        raise ScenarioError(f"realism must be a preset name, got {value!r}")
    realism = resolve_realism(value)       # ScenarioError names a bad preset or knob
    return value.strip() if isinstance(value, str) else realism


def parse_overrides(values: Mapping[str, Any] | None, source: str = "python") -> Overrides:
    """The overrides in `values` (only OVERRIDE_KEYS are read), validated: one ScenarioError
    line naming the key for a bad value. source: 'launch' (strings), 'parameters' (ROS
    parameter values), 'study' (YAML values) or 'python' (keywords; a Realism accepted)."""
    if source not in SOURCES:
        raise ValueError(f"source must be one of {', '.join(SOURCES)}, got {source!r}")
    out: dict[str, Any] = {}
    for key in OVERRIDE_KEYS:
        value = (values or {}).get(key)
        if _absent(value):
            continue
        if key == "bag_model":
            out[key] = _choice(key, value, BAG_MODELS + (NO_BAG,))
        elif key == "bag_variant":
            out[key] = _choice(key, value, bag_variants())
        elif key == "fem_solver":
            out[key] = _choice(key, value, FEM_SOLVERS)
        elif key == "grasp":
            out[key] = _choice(key, value, grasp_names())
        elif key == "flight_mode":
            out[key] = _choice(key, value, tuple(flight_modes.names()))
        elif key == "bag_resolution":
            out[key] = _number(key, value, int, *RESOLUTION_RANGE, "nodes")
        elif key == "bag_mass":
            out[key] = _number(key, value, float, *MASS_RANGE, "kg")
        elif key == "robots":
            out[key] = _robots(value)
        elif key == "realism":
            out[key] = _realism(value, source)
    return Overrides(**out)
