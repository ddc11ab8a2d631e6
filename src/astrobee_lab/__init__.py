"""In-process experiments on the simulator, planner and control libraries (no router, no
processes): `flight.Flight` flies one cargo-transport leg; `envs.AstrobeeCargoEnv` is the
Gymnasium environment built on it, registered here as AstrobeeCargo-v0."""
from __future__ import annotations

ENV_ID = "AstrobeeCargo-v0"


def register_envs() -> None:
    """Register AstrobeeCargo-v0 with Gymnasium (once; a no-op when gymnasium is absent)."""
    try:
        import gymnasium
    except ImportError:       # the flight library works without it
        return
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point="astrobee_lab.envs:AstrobeeCargoEnv",
                           disable_env_checker=False)


register_envs()
