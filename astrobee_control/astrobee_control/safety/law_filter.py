"""One robot's CBF safety filter as a control loop uses it (no transport).

LawFilter wraps a SafetyFilter with what every user of it needs beside the QP: the carried
bag's mass properties and extent (rebuilt only when the held bag moved by a centimetre), the
flight mode (set only when it changes), tick counters, and the diagnostics' content and pace
(latched status published when the active/fallback state changes, at most `diagnostics_rate` Hz
otherwise). safety_filter_node (a process of its own), controller_node with `safety:=true`
(in-process, no extra hop) and astrobee_lab.flight.Flight (`safety=True`) all filter through
it, so the three give the same command for the same input.

    lf = LawFilter(flight_modes.get("nominal"))
    lf.observe_bag(obs, state)                 # a BagObservation, or None when released
    res = lf.apply(force, torque, state)       # SafetyResult; counts the tick
    if lf.diagnostics_due(res, t): level, message, values = lf.status(res)
"""
from __future__ import annotations

from typing import Any

import numpy as np

from astrobee.flight_modes import FlightMode

from .. import mass as mp
from ..mass import MassProperties
from ..pd import State
from .filter import SafetyFilter, SafetyResult
from .geometry import box_corners
from .load import carried_load

OK, WARN, ERROR = 0, 1, 2                 # diagnostic_msgs/DiagnosticStatus levels
DEFAULT_MARGIN = 0.05                     # m the filter's boundary sits outside the keep-in boxes


def check_margin(margin: float) -> float:
    """A margin parameter as metres in [0, 0.5); ValueError otherwise."""
    margin = float(margin)
    if not (np.isfinite(margin) and 0.0 <= margin < 0.5):
        raise ValueError(f"margin must be in [0, 0.5) m, not {margin}")
    return margin


class LawFilter:
    """A SafetyFilter plus the carried bag, counters and diagnostics of one robot."""

    def __init__(self, flight_mode: FlightMode, robot_mass: MassProperties | None = None, *,
                 margin: float = DEFAULT_MARGIN, diagnostics_rate: float = 2.0) -> None:
        self.robot_mass = robot_mass if robot_mass is not None else mp.robot()
        self.filter = SafetyFilter(flight_mode, self.robot_mass, margin=check_margin(margin))
        self.mode = flight_mode
        self.extent: list = []
        self._bag_key: tuple | None = None     # rounded offset/rotation/mass of the held bag
        self.ticks = self.active_ticks = self.fallback_ticks = 0
        self._diag_key: tuple[bool, bool] | None = None
        self._diag_t = -1e9
        self._changed = False                  # the last diagnostics_due() saw a new state
        self.set_diagnostics_rate(diagnostics_rate)

    # ---- inputs -----------------------------------------------------------------------
    def set_diagnostics_rate(self, rate: float) -> None:
        """At most `rate` Hz for unchanged diagnostics (0: only on a change)."""
        self.diag_period = 1.0 / rate if rate > 0 else float("inf")

    def set_flight_mode(self, mode: FlightMode) -> None:
        """The flight mode's force/torque/rate limits (set in the QP only on a change)."""
        if mode is not self.mode:
            self.filter.set_flight_mode(mode)
            self.mode = mode

    @property
    def carrying(self) -> bool:
        return self._bag_key is not None

    def observe_bag(self, obs: Any, state: State) -> str:
        """The held bag (a law.BagObservation) or None (released / not known). Returns what
        changed, for a log line: "attached", "released" or ""."""
        if obs is None:
            return self.release()
        offset, r_rel = obs.offset_in(state)
        # a held bag sways by millimetres: rebuild the envelope only when it moved by 1 cm
        key = (tuple(np.round(offset, 2)), tuple(np.round(r_rel, 2).ravel()), obs.mass)
        if key == self._bag_key:
            return ""
        mprops, com = carried_load(self.robot_mass, obs.mass, obs.size, offset, r_rel)
        self.filter.set_mass(mprops, com)
        self.extent = box_corners(offset, obs.size, r_rel)
        event = "" if self._bag_key is not None else "attached"
        self._bag_key = key
        return event

    def release(self) -> str:
        """No bag held: the robot's envelope and mass only. "released" when one was held."""
        if self._bag_key is None:
            return ""
        self.filter.set_mass(self.robot_mass)
        self.extent, self._bag_key = [], None
        return "released"

    # ---- the filter -------------------------------------------------------------------
    def apply(self, force: np.ndarray, torque: np.ndarray, state: State) -> SafetyResult:
        """The closest safe wrench to (force, torque) (BODY frame) at `state`; counts the tick.
        ValueError/ArithmeticError from the filter pass through (nothing counted)."""
        res = self.filter.filter(force, torque, state, extent=self.extent)
        self.ticks += 1
        self.active_ticks += bool(res.active)
        self.fallback_ticks += bool(res.fallback)
        return res

    # ---- diagnostics ------------------------------------------------------------------
    def diagnostics_due(self, res: SafetyResult, t: float) -> bool:
        """Whether the diagnostics of `res` at time t (s) are to be published: on a change of
        the active/fallback state, else at most every diag_period; a clock gone back (a
        simulation reset) starts the pace anew. Marks them published."""
        key = (bool(res.active), bool(res.fallback))
        if key == self._diag_key and 0.0 <= t - self._diag_t < self.diag_period:
            return False
        self._changed = key != self._diag_key
        self._diag_key, self._diag_t = key, t
        return True

    def transition(self, res: SafetyResult) -> str:
        """A log line when the last diagnostics_due() saw the state change, else ""."""
        if not self._changed:
            return ""
        what = ("fallback: maximum braking" + (f" ({res.reason})" if res.reason else "")
                if res.fallback else "active" if res.active else "transparent")
        return f"safety filter {what} (min barrier {res.min_barrier:.3f} m)"

    def status(self, res: SafetyResult) -> tuple[int, str, list[tuple[str, str]]]:
        """(level, message, key/value pairs) of the diagnostics: OK transparent, WARN the
        command changed, ERROR the maximum braking wrench was sent."""
        level = ERROR if res.fallback else WARN if res.active else OK
        message = ("fallback: maximum braking wrench" if res.fallback
                   else "active: command changed" if res.active else "transparent")
        pairs = [("active", str(bool(res.active)).lower()),
                 ("delta_norm", f"{res.delta_norm:.6g}"),
                 ("slack", f"{res.slack:.6g}"),
                 ("min_barrier", f"{res.min_barrier:.6g}"),
                 ("omega_barrier", f"{res.omega_barrier:.6g}"),
                 ("fallback", str(bool(res.fallback)).lower()),
                 ("reason", res.reason or ""),
                 ("ticks", str(self.ticks)),
                 ("active_ticks", str(self.active_ticks)),
                 ("fallback_ticks", str(self.fallback_ticks))]
        return level, message, pairs
