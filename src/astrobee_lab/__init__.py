"""In-process experiments on the simulator, planner and control libraries (no router, no
processes): `flight.Flight` flies one cargo-transport leg; `envs` are the Gymnasium
environments built on it (registered as AstrobeeCargo-v0 when gymnasium is importable)."""
