"""The ROS edge the controller and safety-filter nodes share: the EKF state decoded, the carried
bag as a node knows it (bag_mass / bag_size parameters over /sim/scenario, /sim/bag/state as a
BagObservation) and the latched <ns>/gnc/ctl/safety diagnostics publisher. Neither node imports
the other."""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from astrobee import flight_modes
from astrobee import msgconv as mc
from astrobee import rotations as rot
from astrobee.overrides import MASS_RANGE
from roszen.parameters import Parameter, runtime

from .law import BagObservation
from .pd import State
from .safety.law_filter import LawFilter, SafetyResult

SAFETY = "gnc/ctl/safety"                     # latched diagnostics (DiagnosticArray)


BAG_SIZE_MAX = 1.0                  # m per side of a bag_size parameter (a double CTB: 0.5)


def check_bag_mass(mass: float) -> None:
    """A bag_mass parameter: <= 0 (the scenario's) or a mass sim_node could simulate (kg)."""
    if mass > 0 and not MASS_RANGE[0] <= mass <= MASS_RANGE[1]:
        raise ValueError(f"bag_mass must be <= 0 (the scenario's) or {MASS_RANGE[0]:g}.."
                         f"{MASS_RANGE[1]:g} kg, got {mass:g}")


def bag_descriptors(bag: Callable[[], "CarriedBag"]) -> dict[str, Any]:
    """bag_mass and bag_size applied at run time to `bag()`, within sim_node's ranges."""
    return {
        "bag_mass": runtime(lambda v: setattr(bag(), "mass_param", float(v)),
                            max_value=MASS_RANGE[1], validator=check_bag_mass),
        "bag_size": runtime(lambda v: setattr(bag(), "size_param", size_override(v)),
                            min_value=0.0, max_value=BAG_SIZE_MAX, validator=size_override),
    }


def size_override(size: Any) -> np.ndarray | None:
    """A bag_size parameter as the size it sets (three positive metres), None for zeros."""
    size = list(size)
    if len(size) != 3 or not all(np.isfinite(s) for s in size):
        raise ValueError(f"bag_size must be three finite numbers (m), got {size}")
    return np.asarray(size, float) if all(s > 0 for s in size) else None


def ekf_state(msg: Any) -> State:
    """EkfState -> State (world position and velocity, BODY omega), checked and normalised;
    ValueError/AttributeError/TypeError for a malformed or non-finite sample."""
    state = State(mc.vec(msg.pose.position), mc.vec(msg.velocity), mc.quat(msg.pose.orientation),
                  mc.vec(msg.omega))
    vals = np.concatenate([state.position, state.velocity, state.orientation, state.omega])
    if not np.all(np.isfinite(vals)) or np.linalg.norm(state.orientation) < 1e-6:
        raise ValueError("non-finite state")
    state.orientation = rot.normalize(state.orientation)
    return state


class FlightModeParameter:
    """The node's flight_mode parameter shows the mode in effect. A mode announced on
    <ns>/mob/flight_mode is taken when it differs from the last one announced (the latched
    sample again, or the sim saying the same mode, does not undo a `param set`); a mode taken
    from elsewhere (a segment's) goes through in_effect too."""

    def __init__(self, node: Any, apply: Callable[[Any], None]) -> None:
        self.node, self.apply = node, apply
        self.announced: str | None = None       # the last mode /mob/flight_mode said

    def on_announced(self, name: str) -> bool:
        """A /mob/flight_mode sample: True when it changed the mode (UnknownFlightMode raises)."""
        if name == self.announced:
            return False
        mode = flight_modes.get(name)
        self.announced = name
        self.in_effect(mode)
        return True

    def in_effect(self, mode: Any) -> None:
        """Fly `mode`; the parameter is set to its name (its on_change applies it) or, when it
        shows it already, the mode applied directly."""
        if self.node.get_parameter("flight_mode").value != mode.name and \
                self.node.set_parameter(Parameter("flight_mode", value=mode.name)).successful:
            return
        self.apply(mode)


class CarriedBag:
    """What a node knows of the carried bag: mass and size from /sim/scenario, each overridden
    by the bag_mass / bag_size parameters when they are set (> 0)."""

    def __init__(self, mass_param: float, size_param: list) -> None:
        self.mass_param = float(mass_param)
        size = list(size_param)
        self.size_param = np.asarray(size, float) if len(size) == 3 and all(s > 0 for s in size) \
            else None
        self.scenario: tuple[float, np.ndarray] | None = None     # (mass, size) of /sim/scenario

    def on_scenario(self, msg: Any) -> None:
        """Take a ScenarioInfo; ValueError (and nothing changed) when its bag figures are bad."""
        if not msg.carrying_bag:
            self.scenario = None
            return
        size = mc.vec(msg.bag_size)
        # mass 0: the sim tells no bag mass (realism bag_mass_told 0); the law flies without it
        if not (np.isfinite(msg.bag_mass) and msg.bag_mass >= 0 and np.all(np.isfinite(size))
                and np.all(size > 0)):
            raise ValueError(f"bag mass {msg.bag_mass} / size {size.tolist()}")
        self.scenario = (float(msg.bag_mass), size)

    def figures(self) -> tuple[float, np.ndarray] | None:
        """(mass, size) of the carried bag, or None when neither parameters nor scenario say."""
        base = self.scenario
        mass = self.mass_param if self.mass_param > 0 else (base[0] if base else None)
        size = self.size_param if self.size_param is not None else (base[1] if base else None)
        return None if mass is None or size is None else (mass, size)

    def observe(self, msg: Any) -> BagObservation | None:
        """A BagState as a BagObservation, None when the bag is not held or its figures are not
        known; ValueError for a non-finite pose."""
        attached = bool(len(msg.attached)) and bool(np.any(np.asarray(msg.attached, bool)))
        figures = self.figures()
        if not attached or figures is None:
            return None
        p_bag, q_bag = mc.pose(msg.pose)
        if not (np.all(np.isfinite(p_bag)) and np.all(np.isfinite(q_bag))
                and float(q_bag @ q_bag) > 1e-12):
            raise ValueError("non-finite bag pose")
        return BagObservation(p_bag, rot.normalize(q_bag), mc.vec(msg.velocity), mc.vec(msg.omega),
                              True, figures[0], figures[1], str(msg.model))


class SafetyDiagnostics:
    """The latched <ns>/gnc/ctl/safety publisher of a node that filters through a LawFilter
    (this node, or a controller_node with safety:=true): one DiagnosticStatus named
    "safety_filter", the node's namespace as hardware_id, the LawFilter's level, message and
    values; on a state change and at the LawFilter's pace, with one log line per change."""

    def __init__(self, node: Any, law_filter: LawFilter) -> None:
        from roszen import runtime as roszen
        from roszen.runtime import LATCHED

        M = roszen.message_class
        self.DiagnosticArray = M("diagnostic_msgs/msg/DiagnosticArray")
        self.DiagnosticStatus = M("diagnostic_msgs/msg/DiagnosticStatus")
        self.KeyValue = M("diagnostic_msgs/msg/KeyValue")
        self.node, self.log, self.lf = node, node.get_logger(), law_filter
        self.pub = node.create_publisher("diagnostic_msgs/msg/DiagnosticArray", SAFETY, LATCHED)

    def publish(self, res: SafetyResult, stamp: Any, t: float) -> None:
        """Publish the diagnostics of `res` (stamped `stamp`, sim time t) when they are due."""
        if not self.lf.diagnostics_due(res, t):
            return
        line = self.lf.transition(res)
        if line:
            self.log.info(line)
        level, message, pairs = self.lf.status(res)
        st = self.DiagnosticStatus()
        st.level = level
        st.name = "safety_filter"
        st.hardware_id = self.node.get_namespace() if hasattr(self.node, "get_namespace") else ""
        st.message = message
        kvs = []
        for k, v in pairs:
            kv = self.KeyValue()
            kv.key, kv.value = k, v
            kvs.append(kv)
        st.values = kvs
        arr = self.DiagnosticArray()
        arr.header.stamp = stamp
        arr.status = [st]
        self.pub.publish(arr)
