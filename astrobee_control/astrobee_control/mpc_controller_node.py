"""mpc_controller_node: the sampling MPC (mpc.MpcLaw) on controller_node's topics and services.

Parameters beyond every controller's: samples, horizon, replan_period, model (reduced |
pybullet), handle (the identified bag model whose handle model A starts with; the observed bag
model's is used once a bag is seen), pybullet_bag (constraint | rigid), workers, settle_time,
seed and the cost weights (mpc.MpcConfig); the attitude-aware mode: attitude (false), and with
it attitude_share, torque_margin, time_scale_min, max_delay, w_attitude, w_momentum, w_delay.
"""
from __future__ import annotations

import sys

from . import controller_node
# the law's parameters and factories live with the law (in-process flights use them too)
from .mpc import PARAMETERS, make_mpc_law, make_rollout_model  # noqa: F401


def main(argv: list[str] | None = None) -> int:
    """Entry point (`ros2 run astrobee_control mpc_controller_node`)."""
    return controller_node.main(make_mpc_law, "mpc_controller_node", PARAMETERS, argv)


if __name__ == "__main__":
    sys.exit(main())
