"""HoldLaw: the smallest ControlLaw (hold the first pose seen, refuse segments).

It exists to prove the seam: a second law runs in controller_node with no node code of its own
(tests/control/test_controller_node_graph.py), and it is a safe stand-in controller.
"""
from __future__ import annotations

from astrobee.flight_modes import FlightMode

from astrobee.msgconv import MotionState

from .law import BagObservation, Step, carried_mass
from .mass import MassProperties
from .pd import MODE_STOP, PdFeedback, Reference, State
from .reference import SampledTrajectory

STOPPED = MotionState.STOPPED


class HoldLaw:
    """Station keeping at the first measured pose; segments are refused (result REFUSED)."""

    name = "hold"

    def __init__(self, flight_mode: FlightMode, mass: MassProperties, ) -> None:
        self.pd = PdFeedback(flight_mode, mass)
        self.robot_mass = mass
        self.state = STOPPED
        self.segment_result = ""
        self.hold: Reference | None = None
        self._event = ""

    @property
    def flight_mode(self) -> FlightMode:
        return self.pd.flight_mode

    def set_flight_mode(self, mode: FlightMode) -> None:
        self.pd.set_flight_mode(mode)

    def set_mass(self, mass: MassProperties) -> None:
        self.robot_mass = mass
        self.pd.set_mass(mass)

    def observe_bag(self, bag: BagObservation | None, robot: State | None) -> None:
        self.pd.set_mass(carried_mass(self.robot_mass, bag, robot))

    def follow(self, traj: SampledTrajectory, now: float) -> None:
        self.segment_result = "REFUSED"
        self._event = f"hold law: segment of {traj.duration:.1f} s refused, holding"

    def stop(self, state: State, now: float, why: str = "stop requested") -> None:
        self._event = f"{why}: already holding"

    def rehold(self, state: State, why: str) -> None:
        self.hold = Reference.hold(state.position, state.orientation)
        self.pd.reset()
        self._event = why

    def update(self, state: State, now: float, dt: float) -> Step:
        if self.hold is None:
            self.rehold(state, "holding the start pose")
        event, self._event = self._event, ""
        return Step(self.pd.step(state, self.hold, dt), self.hold, MODE_STOP, self.state, event)
