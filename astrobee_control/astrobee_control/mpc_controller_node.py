"""mpc_controller_node: the sampling MPC (registry entry `mpc`: mpc.CONTROLLER) on
controller_node's topics and services.

Parameters beyond every controller's (mpc.PARAMETERS): samples, horizon, replan_period, model
(reduced | pybullet), handle (the identified bag model whose handle model A starts with; the
observed bag model's is used once a bag is seen), pybullet_bag (constraint | rigid), workers,
settle_time, seed and the cost weights (mpc.MpcConfig); the attitude-aware mode: attitude
(false), and with it attitude_share, torque_margin, time_scale_min, max_delay, w_attitude,
w_momentum, w_delay.
"""
from __future__ import annotations

import sys

from .controller_node import run_registered


def main(argv: list[str] | None = None) -> int:
    """Entry point (`ros2 run astrobee_control mpc_controller_node`)."""
    return run_registered("mpc", argv)


if __name__ == "__main__":
    sys.exit(main())
