"""The simulator seam: what sim_node needs of a physics backend, and how to pick one.

sim_node (the ROS edge) talks to a `SimBackend` only, so a backend can be swapped without
touching node code: the pybullet `Simulation` (ISS walls, Astrobee URDF, four bag models) is the
reference; `RigidSim` (rigid_backend.py, numpy only) is a light stand-in for graph tests of the
controller and the mission. Both take a typed `astrobee.scenario.Scenario`, validate a reset
request completely before they touch the running world, and apply the same per-axis flight-mode
force clip and propulsion watchdog.

This module is the protocol and what every backend shares (the contact and bag-info records,
the seed and scenario checks, the simulator defaults); it imports no backend: `make_backend`
finds the implementation by its module path in BACKENDS, so an implementation may import this
module and never the other way round.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from astrobee.flight_modes import FlightMode
from astrobee.overrides import OVERRIDE_KEYS, Overrides, parse_overrides
from astrobee.scenario import Scenario, ScenarioError

from .bags.base import BagState
from .world import World

# backend name -> "module:class" of its implementation (imported when asked for)
_IMPLEMENTATIONS = {"pybullet": "astrobee_sim.simulation:Simulation",
                    "rigid": "astrobee_sim.rigid_backend:RigidSim"}
BACKENDS = tuple(_IMPLEMENTATIONS)
MAX_SEED = 2**63 - 1          # Reset.srv carries an int64


@dataclass
class Contact:
    """One contact of a robot or the bag with the station (world frame)."""

    body_a: str
    body_b: str
    position: np.ndarray
    normal: np.ndarray
    normal_force: float


@dataclass(frozen=True)
class BagInfo:
    """What the node publishes about the bag besides its state (model, variant, parts)."""

    model: str
    variant: str
    nodes: int              # FEM nodes, or rigid parts of the reduced models


def check_seed(seed: Any) -> int:
    """A reset seed: an integer 0..2**63-1 (ScenarioError otherwise, before anything changes)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ScenarioError(f"seed must be a non-negative integer, got {seed!r}")
    s = int(seed)
    if not 0 <= s <= MAX_SEED:
        raise ScenarioError(f"seed must be a non-negative integer (0..2**63-1), got {s}")
    return s


def standing_overrides(overrides: Overrides | None, keys: dict[str, Any]) -> Overrides:
    """The overrides a backend keeps for every reset by name: an Overrides, or its keys as
    keywords (astrobee.overrides.OVERRIDE_KEYS) parsed by the one parser (ScenarioError for a
    bad value); TypeError for any other keyword."""
    unknown = sorted(set(keys) - set(OVERRIDE_KEYS))
    if unknown or (overrides is not None and keys):
        raise TypeError(f"a backend takes an Overrides or the keywords {OVERRIDE_KEYS}, got "
                        f"{unknown or sorted(keys)}")
    return overrides if overrides is not None else parse_overrides(keys, source="python")


def resolve_scenario(scenario: str | dict | Scenario | None, current: Scenario | None,
                     overrides: Overrides) -> Scenario:
    """The Scenario a reset asks for: a Scenario as given; a name (config/scenarios) or a
    scenario mapping, with the backend's standing overrides; None/'' the current one. Raises
    ScenarioError (and the caller changes nothing)."""
    if isinstance(scenario, Scenario):
        return scenario
    if isinstance(scenario, dict):
        return Scenario.from_dict(scenario, str(scenario.get("name", "custom"))).override(overrides)
    if scenario is None or scenario == "":
        if current is None:
            scenario = "node2_to_jem"
        else:
            return current
    if not isinstance(scenario, str):
        raise ScenarioError(f"scenario must be a name or a Scenario, got {type(scenario).__name__}")
    return Scenario.load(scenario, overrides)


@runtime_checkable
class SimBackend(Protocol):
    """Exactly what sim_node uses of a simulator (see the module docstring)."""

    time: float                 # s of sim time since the last reset
    dt: float                   # s per physics step
    steps: int                  # physics steps since the last reset
    seed: int
    scenario: Scenario          # what the world was built from (overrides applied)
    watchdog_timeout: float     # s without a command before the wrench is zeroed
    world: World                # keep-in boxes and wall slabs (markers, clearance)

    def robot_names(self) -> list[str]:
        """Robot namespaces ('' = the default robot), in the scenario's order."""

    def flight_mode_of(self, robot: str) -> FlightMode:
        """The robot's current flight mode (its propulsion limits clip the commands)."""

    def set_flight_mode(self, name: str, robot: str | None = None) -> None:
        """Change one robot's flight mode, or every robot's (raises UnknownFlightMode)."""

    def command(self, wrench_body: Any, robot: str = "") -> bool:
        """Hold a body-frame wrench [fx fy fz tx ty tz] (clipped); False if rejected."""

    def step(self, n: int = 1) -> None:
        """Advance n physics steps (watchdog checked before each)."""

    def robot_state(self, robot: str = "") -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(position, orientation [x,y,z,w], velocity, angular velocity), world frame."""

    def arm_joints(self, robot: str = "") -> tuple[float, ...]:
        """The robot's arm joint positions (robot.ARM_JOINTS: proximal, distal rad; fingers m)."""

    def faulted(self, robot: str) -> bool:
        """True while the propulsion watchdog holds the robot's wrench at zero."""

    def bag_info(self) -> BagInfo | None:
        """The bag's model facts, None without a bag."""

    def bag_state(self) -> BagState | None:
        """The bag's pose, twist, deformation and grasps, None without a bag."""

    def bag_points(self) -> np.ndarray | None:
        """World points of the bag (FEM nodes or box corners), None without a bag."""

    def contacts(self) -> list[Contact]:
        """Contacts of the robots and the bag with the station walls."""

    def clearance(self, robot_positions: list | None = None) -> tuple[float, float]:
        """(robot envelope, bag) smallest wall distance in m; -1 for an absent bag."""

    def reset(self, scenario: str | Scenario | None = None, seed: int | None = None) -> None:
        """Rebuild the world; a bad request raises ScenarioError and changes nothing."""

    def close(self) -> None:
        """Free the backend's resources."""


def make_backend(kind: str, scenario: str | Scenario, seed: int = 0, **kw: Any) -> SimBackend:
    """Build a backend by name ('pybullet' | 'rigid'); kw are the backend's keywords (overrides,
    physics_rate, gui, ...). Only the asked-for implementation is imported (pybullet for
    'pybullet' alone)."""
    where = _IMPLEMENTATIONS.get(kind)
    if where is None:
        raise ValueError(f"unknown backend {kind!r}; known: {', '.join(BACKENDS)}")
    module, cls = where.split(":")
    return getattr(importlib.import_module(module), cls)(scenario, seed=seed, **kw)
