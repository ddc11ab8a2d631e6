"""mpc_controller_node: the sampling MPC (mpc.MpcLaw) on controller_node's topics and services.

Parameters beyond every controller's: samples, horizon, replan_period, model (reduced |
pybullet), handle (the identified bag model whose handle model A starts with; the observed bag
model's is used once a bag is seen), pybullet_bag (constraint | rigid), workers, settle_time,
seed and the cost weights (mpc.MpcConfig).
"""
from __future__ import annotations

import sys
from dataclasses import asdict

from astrobee.flight_modes import FlightMode

from . import controller_node
from .mass import MassProperties
from .mpc import MODELS, MpcConfig, MpcLaw

_CFG = asdict(MpcConfig())
PARAMETERS = {**{k: _CFG[k] for k in ("samples", "horizon", "replan_period", "rollout_dt",
                                      "sigma_position", "sigma_velocity", "w_track", "w_collision",
                                      "w_clearance", "clearance_margin", "w_effort", "w_relvel",
                                      "seed")},
              "model": "reduced", "handle": "fem", "pybullet_bag": "constraint", "workers": 2,
              "settle_time": 5.0}


def make_rollout_model(params: dict):
    """The rollout model the parameters name (ValueError with one line otherwise)."""
    model = str(params.get("model", "reduced"))
    if model == "reduced":
        from .reduced_model import ReducedModel, identified_handles
        handles = identified_handles()
        name = str(params.get("handle", "fem"))
        if name not in handles:
            raise ValueError(f"no identified handle {name!r} in config/reduced_models.yaml; "
                             f"known: {', '.join(handles) or 'none'}")
        return ReducedModel(handles[name], handles)
    if model == "pybullet":
        from .rollout_pybullet import PybulletModel
        return PybulletModel(int(params.get("workers", 2)), str(params.get("pybullet_bag", "constraint")))
    raise ValueError(f"unknown model {model!r}; known: {', '.join(MODELS)}")


def make_mpc_law(flight_mode: FlightMode, mass: MassProperties, params: dict) -> MpcLaw:
    """The MPC law of the node's parameters (ValueError with one line for a bad value)."""
    config = MpcConfig.from_params(params)
    settle = float(params.get("settle_time", 5.0))
    if not settle > 0:
        raise ValueError(f"settle_time must be > 0 s, got {settle:g}")
    return MpcLaw(flight_mode, mass, make_rollout_model(params), config, settle_time=settle)


def main(argv: list[str] | None = None) -> int:
    """Entry point (`ros2 run astrobee_control mpc_controller_node`)."""
    return controller_node.main(make_mpc_law, "mpc_controller_node", PARAMETERS, argv)


if __name__ == "__main__":
    sys.exit(main())
