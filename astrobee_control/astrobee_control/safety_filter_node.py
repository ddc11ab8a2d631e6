"""safety_filter_node: the CBF-QP safety filter (safety/filter.py) between a controller and the
robot.

Subscribes <ns>/gnc/ctl/command_nominal (FamCommand, the controller's BODY-frame wrench),
<ns>/gnc/ekf (EkfState: position, velocity (world), orientation, omega (body)),
<ns>/mob/flight_mode (latched: the force/torque limits), /sim/scenario (latched: carrying_bag,
bag_size, bag_mass) and /sim/bag/state (the bag pose: where its extent sits relative to the robot
while attached). For each nominal command publishes the filtered FamCommand on
<ns>/gnc/ctl/command with the same header stamp (the sim's lockstep waits for that stamp) and
every other field copied; before any state has arrived the nominal command passes unchanged.
Latched diagnostics on <ns>/gnc/ctl/safety (diagnostic_msgs/DiagnosticArray, one status: OK,
WARN when the filter changed the command, ERROR when it fell back to the maximum braking wrench;
values active, delta_norm, slack, min_barrier, omega_barrier (w_max^2 - |w|^2), fallback, reason), published when the
active/fallback state changes and at most `diagnostics_rate` Hz otherwise.

The filtering itself (carried bag, counters, diagnostics' content) is safety.LawFilter, which a
controller_node with `safety:=true` runs in its own process (no extra hop; the launch's default
way): this node is for a controller that is not ours (`astrobee launch cargo_transport
safety:=node`). Both publish the same diagnostics through node_io.SafetyDiagnostics.

Callbacks never raise: a bad or non-finite sample is logged and dropped.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from astrobee import flight_modes
from astrobee import msgconv as mc
from roszen.runtime import node_main
from roszen.parameters import read_only, runtime

from .node_io import CarriedBag, SafetyDiagnostics, bag_descriptors, ekf_state
from .pd import State
from .safety.law_filter import DEFAULT_MARGIN, LawFilter

COMMAND_NOMINAL = "gnc/ctl/command_nominal"   # the controller's command, before the filter
STATE_MAX_AGE = 0.5                           # s of sim time: an older state is not used

PARAMETERS: dict[str, Any] = {
    "flight_mode": flight_modes.get().name,   # config's default until /mob/flight_mode says
    "margin": DEFAULT_MARGIN,       # m the filter's boundary sits outside the keep-in boxes
    "bag_mass": -1.0,               # kg; < 0 = the scenario's
    "bag_size": [0.0, 0.0, 0.0],    # m; zeros = the scenario's
    "diagnostics_rate": 2.0,        # Hz at most for unchanged diagnostics
}


class SafetyFilterNode:
    """Wiring of one LawFilter to topics."""

    def __init__(self, argv: list[str] | None = None) -> None:
        from roszen import runtime as roszen
        from roszen.runtime import LATCHED

        self.node = n = roszen.Node("safety_filter", argv=argv)
        self.log = n.get_logger()
        values = {k: n.declare_parameter(k, d, self._descriptor(k)).value
                  for k, d in PARAMETERS.items()}
        mode = flight_modes.get(str(values["flight_mode"]) or None)
        self.bag = CarriedBag(values["bag_mass"], values["bag_size"])
        self.lf = LawFilter(mode, margin=float(values["margin"]),
                            diagnostics_rate=float(values["diagnostics_rate"]))
        self.filter = self.lf.filter
        self._state: State | None = None
        self._state_t: float | None = None

        M = roszen.message_class
        self.FamCommand = M("astrobee_msgs/msg/FamCommand")
        self.diagnostics = SafetyDiagnostics(n, self.lf)
        n.create_subscription("astrobee_msgs/msg/EkfState", mc.EKF, self._on_ekf, 10)
        n.create_subscription("astrobee_msgs/msg/FlightMode", mc.FLIGHT_MODE, self._on_flight_mode,
                              LATCHED)
        n.create_subscription("astrobee_msgs/msg/ScenarioInfo", mc.SIM_SCENARIO, self._on_scenario,
                              LATCHED)
        n.create_subscription("astrobee_msgs/msg/BagState", mc.BAG_STATE, self._on_bag, 10)
        n.create_subscription("astrobee_msgs/msg/FamCommand", COMMAND_NOMINAL, self._on_command, 10)
        # declared last: a publisher of the command in the graph says every input above is
        # subscribed (the mission's deterministic start waits for it; callbacks run only once
        # the node spins, after this constructor)
        self.pub_cmd = n.create_publisher("astrobee_msgs/msg/FamCommand", mc.COMMAND, 10)
        self.log.info(f"safety filter up: flight mode {mode.name}, margin "
                      f"{self.filter.margin:.2f} m, {len(self.filter.boxes)} candidate boxes")

    @property
    def ticks(self) -> int:
        return self.lf.ticks

    # ---- parameters -------------------------------------------------------------------
    def _descriptor(self, name: str) -> Any:
        """flight_mode, bag_mass, bag_size and diagnostics_rate are applied at run time; margin
        is read-only (the candidate boxes are grown by it once, at start)."""
        if name == "flight_mode":
            return runtime(lambda v: self.lf.set_flight_mode(flight_modes.get(str(v))),
                           choices=flight_modes.names())
        if name in ("bag_mass", "bag_size"):
            return bag_descriptors(lambda: self.bag)[name]
        if name == "diagnostics_rate":
            return runtime(lambda v: self.lf.set_diagnostics_rate(float(v)), min_value=0.0)
        return read_only()

    # ---- inputs -----------------------------------------------------------------------
    def _on_flight_mode(self, msg: Any) -> None:
        try:
            self.lf.set_flight_mode(flight_modes.get(msg.name))
            self.log.info(f"flight mode {msg.name}")
        except (flight_modes.UnknownFlightMode, AttributeError, TypeError, ValueError) as exc:
            self.log.error(f"flight mode dropped: {exc}")

    def _on_scenario(self, msg: Any) -> None:
        try:
            self.bag.on_scenario(msg)
        except (AttributeError, TypeError, ValueError) as exc:
            self.log.warn(f"bad scenario description dropped: {exc}")
            return
        if self.bag.scenario is None:
            self._log_bag(self.lf.release())

    def _log_bag(self, event: str) -> None:
        if event == "released":
            self.log.info("bag released: robot envelope only")

    def _on_bag(self, msg: Any) -> None:
        try:
            attached = bool(len(msg.attached)) and bool(np.any(np.asarray(msg.attached, bool)))
            state = self._state
            obs = self.bag.observe(msg) if state is not None else None
            if obs is None:
                if not attached:
                    self._log_bag(self.lf.release())
                return
            if self.lf.observe_bag(obs, state) == "attached":
                offset, _ = obs.offset_in(state)
                self.log.info(f"bag attached: {obs.mass:.1f} kg at "
                              f"{np.round(offset, 3).tolist()} m (body frame)")
        except (ValueError, AttributeError, TypeError) as exc:
            self.log.warn(f"bad bag state dropped: {exc}")

    def _on_ekf(self, msg: Any) -> None:
        try:
            state = ekf_state(msg)
            t = mc.stamp_s(msg.header.stamp)
        except (AttributeError, TypeError, ValueError) as exc:
            self.log.warn(f"bad EKF state dropped: {exc}")
            return
        self._state, self._state_t = state, t

    # ---- the filter -------------------------------------------------------------------
    def _on_command(self, msg: Any) -> None:
        try:
            f_nom, t_nom = mc.vec(msg.wrench.force), mc.vec(msg.wrench.torque)
            t = mc.stamp_s(msg.header.stamp)
            if not (np.all(np.isfinite(f_nom)) and np.all(np.isfinite(t_nom))):
                raise ValueError("non-finite wrench")
        except (AttributeError, TypeError, ValueError) as exc:
            self.log.warn(f"bad nominal command dropped: {exc}")
            return
        state = self._state
        if state is None:
            self.pub_cmd.publish(msg)             # no state yet: nothing to filter against
            return
        if self._state_t is not None and t < self._state_t - STATE_MAX_AGE:
            # the clock went back (a simulation reset): this state belongs to the old world
            self._state = self._state_t = None
            self.pub_cmd.publish(msg)
            return
        try:
            res = self.lf.apply(f_nom, t_nom, state)
        except (ValueError, ArithmeticError) as exc:
            self.log.warn(f"nominal command dropped: {exc}")
            return
        out = self.FamCommand()
        for name in ("header", "accel", "alpha", "status", "position_error",
                     "position_error_integrated", "attitude_error", "attitude_error_integrated",
                     "attitude_error_mag", "control_mode"):
            setattr(out, name, getattr(msg, name))
        mc.set_vec(out.wrench.force, res.force)
        mc.set_vec(out.wrench.torque, res.torque)
        self.pub_cmd.publish(out)
        self.diagnostics.publish(res, msg.header.stamp, t)


def main(argv: list[str] | None = None) -> int:
    return node_main.run(SafetyFilterNode, argv)


if __name__ == "__main__":
    raise SystemExit(main())
