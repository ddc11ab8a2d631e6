"""The control-law seam: what controller_node needs of a law, and what it tells the law.

A law is transport-free. controller_node (the ROS edge) feeds it states, segments, the flight
mode, the carried bag and stop requests, and publishes the Step it returns each tick. The PD
law (tracking.PdLaw) is one law, the sampling MPC another; `hold.HoldLaw` is the
smallest one (hold the start pose), used by the tests to prove a second law plugs in.

Contract (times in seconds of sim time; frames as in pd.py):
- update(state, now, dt) -> Step, once per state sample (62.5 Hz); never raises on a finite
  state.
- follow(traj, now): start tracking a segment (CONTROLLING); stop(state, now): hold the pose
  where the stop came (STOPPING -> STOPPED); rehold(state, why): drop everything and hold now
  (after a simulation reset).
- set_flight_mode(mode), set_mass(mass): the robot's limits and its rigid mass properties.
- observe_bag(obs): the carried bag each tick it is published (None when released). The default
  use is mass properties (robot + rigidly held bag); a model-based law also uses its motion.
- state (MotionState value), segment_result ("" while running, else GOAL_REACHED,
  TOLERANCE_TIMEOUT, STOPPED), flight_mode, name.
- Step.candidates / Step.chosen: optional (N, T, 3) and (T, 3) position arrays a sampling law
  considered and chose this tick, published for display; None otherwise.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Callable, Protocol, runtime_checkable

import numpy as np

from astrobee import rotations as rot
from astrobee.flight_modes import FlightMode

from . import mass as mp
from .mass import MassProperties
from .pd import Output, Reference, State
from .reference import SampledTrajectory


@dataclass
class Step:
    """What one control tick of any law produces."""

    output: Output
    reference: Reference
    control_mode: int
    state: int                             # MotionState value after the tick
    event: str                             # non-empty when the state changed this tick (why)
    candidates: np.ndarray | None = None   # (N, T, 3) positions a sampling law considered
    chosen: np.ndarray | None = None       # (T, 3) positions of the candidate it executes


@dataclass
class BagObservation:
    """The cargo bag as the controller sees it (world frame) plus what the scenario says of it."""

    position: np.ndarray
    orientation: np.ndarray
    velocity: np.ndarray
    omega: np.ndarray
    attached: bool
    mass: float
    size: np.ndarray
    model: str = ""

    def offset_in(self, robot: State) -> tuple[np.ndarray, np.ndarray]:
        """(bag centre in the robot body frame, bag -> body rotation matrix)."""
        offset = rot.rotate_inverse(robot.orientation, self.position - robot.position)
        r_rel = rot.to_matrix(robot.orientation).T @ rot.to_matrix(self.orientation)
        return offset, r_rel


def carried_mass(robot_mass: MassProperties, bag: BagObservation | None,
                 robot: State | None) -> MassProperties:
    """Robot mass properties, plus the bag's (rigidly held) when it is attached."""
    if bag is None or not bag.attached or robot is None or bag.mass <= 0:
        return robot_mass
    offset, r_rel = bag.offset_in(robot)
    return mp.with_bag(robot_mass, bag.mass, bag.size, offset, r_rel)


@runtime_checkable
class ControlLaw(Protocol):
    """What controller_node drives (see the module docstring)."""

    name: str
    state: int
    segment_result: str

    @property
    def flight_mode(self) -> FlightMode: ...

    def set_flight_mode(self, mode: FlightMode) -> None: ...

    def set_mass(self, mass: MassProperties) -> None: ...

    def observe_bag(self, bag: BagObservation | None, robot: State | None) -> None: ...

    def follow(self, traj: SampledTrajectory, now: float) -> None: ...

    def stop(self, state: State, now: float, why: str = "stop requested") -> None: ...

    def rehold(self, state: State, why: str) -> None: ...

    def update(self, state: State, now: float, dt: float) -> Step: ...


# a law's factory: (flight mode, robot mass properties, its parameters, complete) -> the law;
# ValueError with one line for a bad parameter
LawFactory = Callable[[FlightMode, MassProperties, dict], ControlLaw]


def carried_reference(ref: Reference, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position, velocity) of the point at body offset c of the robot's reference (world
    frame): where the pair's centre of mass is meant to be when the reference carries the bag."""
    c_ref = rot.to_matrix(rot.normalize(ref.orientation)) @ np.asarray(c, float)
    return (np.asarray(ref.position, float) + c_ref,
            np.asarray(ref.velocity, float) + np.cross(np.asarray(ref.omega, float), c_ref))


def config_parameters(config: Any) -> dict[str, Any]:
    """A law's ROS parameters from its config dataclass's defaults (tuples as lists: the
    parameter types take lists); the config stays the one owner of the defaults."""
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(config).items()}


def check_hold_on_start(params: dict) -> None:
    """hold_on_start, every tracking law's switch: a bool, else one line of ValueError."""
    if not isinstance(params.get("hold_on_start", True), bool):
        raise ValueError(f"hold_on_start must be true or false, got {params['hold_on_start']!r}")
