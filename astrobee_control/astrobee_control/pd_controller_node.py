"""pd_controller_node: the PD tracker (tracking.Tracker) on controller_node.

`ros2 run astrobee_control pd_controller_node --ros-args -p settle_time:=5.0`; the topics,
services and common parameters are controller_node's.
"""
from __future__ import annotations

import sys

from astrobee.flight_modes import FlightMode

from . import controller_node
from .mass import MassProperties
from .tracking import Tracker

PARAMETERS = {
    "settle_time": 5.0,       # s the end of a segment may take to come to rest within tolerance
    "hold_on_start": True,    # hold the first pose seen (else IDLE: zero wrench until a segment)
}


def make_law(flight_mode: FlightMode, mass: MassProperties, params: dict) -> Tracker:
    settle = float(params["settle_time"])
    if not settle > 0:
        raise ValueError(f"settle_time must be > 0 s, got {settle:g}")
    return Tracker(flight_mode, mass, settle_time=settle, hold_on_start=bool(params["hold_on_start"]))


def main(argv: list[str] | None = None) -> int:
    """Entry point (`ros2 run astrobee_control pd_controller_node`)."""
    return controller_node.main(make_law, "pd_controller_node", PARAMETERS, argv)


if __name__ == "__main__":
    sys.exit(main())
