"""pd_controller_node: the PD law (registry entry `pd`: tracking.CONTROLLER) on controller_node.

`ros2 run astrobee_control pd_controller_node --ros-args -p settle_time:=5.0`; the topics,
services and common parameters are controller_node's, the law's are tracking.PARAMETERS.
"""
from __future__ import annotations

import sys

from .controller_node import run_registered


def main(argv: list[str] | None = None) -> int:
    """Entry point (`ros2 run astrobee_control pd_controller_node`)."""
    return run_registered("pd", argv)


if __name__ == "__main__":
    sys.exit(main())
