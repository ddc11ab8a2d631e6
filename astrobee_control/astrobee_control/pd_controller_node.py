"""pd_controller_node: the PD tracker (tracking.Tracker) on controller_node.

`ros2 run astrobee_control pd_controller_node --ros-args -p settle_time:=5.0`; the topics,
services and common parameters are controller_node's.
"""
from __future__ import annotations

import sys

from . import controller_node
from .tracking import PARAMETERS, make_law  # noqa: F401 - the law's factory lives with the law


def main(argv: list[str] | None = None) -> int:
    """Entry point (`ros2 run astrobee_control pd_controller_node`)."""
    return controller_node.main(make_law, "pd_controller_node", PARAMETERS, argv)


if __name__ == "__main__":
    sys.exit(main())
