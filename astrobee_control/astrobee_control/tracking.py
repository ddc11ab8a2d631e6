"""The controller's mobility state machine around the PD law: follow a segment, stop and hold.

Transport-free: the PD ControlLaw (law.py) that controller_node drives.
MotionState values follow NASA ff_msgs/MotionState. Life cycle:
    IDLE (no command yet; zero wrench)  --first state (hold_on_start)-->  STOPPED (hold pose)
    any  --segment-->  CONTROLLING (track it)  --end of segment-->  STOPPING (hold final pose
    until within tolerance and at rest, or settle_time)  -->  STOPPED
    any  --stop request-->  STOPPING (hold the pose where the stop came)  --at rest-->  STOPPED
STOPPED is this law's own report (read from the state it is fed) and it keeps holding there;
it ends no leg: the mission and Flight end a leg when astrobee.task says so (at rest at the
goal on truth for 2 s, or the time budget out), one judge reading one source.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from astrobee import rotations as rot
from astrobee.flight_modes import FlightMode
from astrobee.msgconv import MotionState

from .law import BagObservation, Step, carried_mass, check_hold_on_start
from .mass import MassProperties
from .pd import MODE_IDLE, MODE_NOMINAL, MODE_STOP, Output, PdFeedback, Reference, State
from .reference import SampledTrajectory
from .registry import Controller

# the MotionState values this state machine uses (astrobee.msgconv owns them)
INITIALIZING, IDLE, STOPPED = MotionState.INITIALIZING, MotionState.IDLE, MotionState.STOPPED
IDLING, STOPPING, CONTROLLING = MotionState.IDLING, MotionState.STOPPING, MotionState.CONTROLLING

STOP_SPEED = 0.01    # m/s: "at rest" when stopping
STOP_OMEGA = 0.02    # rad/s

SETTLE_TIME = 5.0    # s the end of a segment may take to come to rest within tolerance

# the PD law's parameters beyond every controller's (name -> default; the one owner of these
# defaults): its node declares them as ROS parameters, in-process flights read them too
PARAMETERS = {
    "settle_time": SETTLE_TIME,
    "hold_on_start": True,    # hold the first pose seen (else IDLE: zero wrench until a segment)
}


class PdLaw:
    """The PD ControlLaw: a segment follower, PdFeedback plus the IDLE/CONTROLLING/STOPPING/
    STOPPED logic."""

    name = "pd"

    def __init__(self, flight_mode: FlightMode, mass: MassProperties,
                 settle_time: float = SETTLE_TIME,
                 hold_on_start: bool = True) -> None:
        self.pd = PdFeedback(flight_mode, mass)
        self.robot_mass = mass
        self.carrying = False
        self.settle_time = settle_time
        self.hold_on_start = hold_on_start
        self.state = IDLE
        self.traj: SampledTrajectory | None = None
        self.hold: Reference | None = None
        self._stopping_since = 0.0
        self._pending_event = ""
        self.segment_result = ""  # "" while running, else GOAL_REACHED / TOLERANCE_TIMEOUT / STOPPED

    @property
    def flight_mode(self) -> FlightMode:
        return self.pd.flight_mode

    def set_flight_mode(self, mode: FlightMode) -> None:
        self.pd.set_flight_mode(mode)

    def set_mass(self, mass: MassProperties) -> None:
        """The robot's own mass properties (a carried bag is added by observe_bag)."""
        self.robot_mass = mass
        self.pd.set_mass(mass)

    def observe_bag(self, bag: BagObservation | None, robot: State | None) -> None:
        """Feed-forward with the rigidly held bag's mass and inertia while it is attached."""
        self.carrying = bag is not None and bag.attached and robot is not None
        self.pd.set_mass(carried_mass(self.robot_mass, bag, robot))

    def _transition(self, state: int, event: str) -> None:
        self.state = state
        self._pending_event = event

    def follow(self, traj: SampledTrajectory, now: float) -> None:
        """Start tracking `traj`; a segment whose first time is already past is shifted to now."""
        if traj.start_time < now:
            traj = traj.shifted(now - traj.start_time)
        self.traj = traj
        self.pd.reset()
        self.segment_result = ""
        self._transition(CONTROLLING, f"segment of {traj.duration:.1f} s accepted")

    def stop(self, state: State, now: float, why: str = "stop requested") -> None:
        """Hold the current pose (zero-velocity reference) until at rest."""
        self.traj = None
        self.hold = Reference.hold(state.position, state.orientation)
        self._stopping_since = now
        if self.segment_result == "" and self.state == CONTROLLING:
            self.segment_result = "STOPPED"
        self._transition(STOPPING, why)

    def rehold(self, state: State, why: str) -> None:
        """Drop any segment and hold `state`'s pose now (after a reset teleported the robot)."""
        self.traj = None
        self.hold = Reference.hold(state.position, state.orientation)
        self.pd.reset()
        self._transition(STOPPED, why)

    def idle(self, why: str = "idle requested") -> None:
        self.traj = None
        self.hold = None
        self._transition(IDLE, why)

    def _within(self, state: State, ref: Reference) -> bool:
        fm = self.flight_mode
        return (float(np.linalg.norm(state.position - ref.position)) <= fm.tolerance_pos
                and rot.angle_between(state.orientation, ref.orientation) <= fm.tolerance_att)

    def _at_rest(self, state: State) -> bool:
        return (float(np.linalg.norm(state.velocity)) < STOP_SPEED
                and float(np.linalg.norm(state.omega)) < STOP_OMEGA)

    def update(self, state: State, now: float, dt: float) -> Step:
        """One control tick at time `now` (s) for the measured `state`."""
        if self.state == IDLE and self.hold_on_start and self.hold is None and self.traj is None:
            self.hold = Reference.hold(state.position, state.orientation)
            self._transition(STOPPED, "holding the start pose")
        if self.state == CONTROLLING and self.traj is not None and now >= self.traj.end_time:
            self.hold = self.traj.final()
            self.traj = None
            self._stopping_since = now
            self._transition(STOPPING, "end of segment")
        elif self.state == STOPPING and self.hold is not None:
            reached = self._within(state, self.hold) and self._at_rest(state)
            timed_out = now - self._stopping_since >= self.settle_time
            if reached or timed_out:
                if self.segment_result == "":
                    self.segment_result = "GOAL_REACHED" if self._within(state, self.hold) \
                        else "TOLERANCE_TIMEOUT"
                self._transition(STOPPED, "at rest" if reached else "settle time elapsed")

        if self.state == CONTROLLING and self.traj is not None:
            ref, mode = self.traj.sample(now), MODE_NOMINAL
        elif self.state in (STOPPING, STOPPED) and self.hold is not None:
            ref, mode = self.hold, MODE_STOP
        else:
            ref = Reference.hold(state.position, state.orientation)
            out = self.pd.step(state, ref, 0.0)
            zero = np.zeros(3)
            out.force, out.torque, out.accel, out.alpha = zero, zero.copy(), zero.copy(), zero.copy()
            return self._step(out, ref, MODE_IDLE)
        return self._step(self.pd.step(state, ref, dt), ref, mode)

    def _step(self, out: Output, ref: Reference, mode: int) -> Step:
        event, self._pending_event = self._pending_event, ""
        return Step(out, ref, mode, self.state, event)


Tracker = PdLaw    # its former name (many call sites)


def check_settle_time(value: Any) -> float:
    """A settle_time parameter (s, > 0), as a float; ValueError with one line otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise ValueError(f"settle_time must be > 0 s, got {value!r}")
    return float(value)


def check_params(params: dict) -> None:
    """The PD law's parameters (complete), checked without building it."""
    check_settle_time(params["settle_time"])
    check_hold_on_start(params)


def make_law(flight_mode: FlightMode, mass: MassProperties, params: dict) -> PdLaw:
    """The PD law of the parameters (PARAMETERS' names; ValueError with one line for a bad value).
    pd_controller_node and in-process flights build their law here."""
    params = {**PARAMETERS, **params}
    return PdLaw(flight_mode, mass, settle_time=check_settle_time(params["settle_time"]),
                   hold_on_start=bool(params["hold_on_start"]))


# the registry entry (astrobee_control.registry; pyproject's astrobee.controllers group)
CONTROLLER = Controller("pd", make_law, PARAMETERS, check_params,
                        "PD tracking of the segment (NASA gains of the flight mode)",
                        executable="pd_controller_node")
