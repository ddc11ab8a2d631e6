"""Cargo-bag models sharing one interface (base.Bag): fem, constraint, composite, rigid."""
from __future__ import annotations

from astrobee.scenario import BAG_MODELS as MODELS
from astrobee.scenario import FEM_SOLVERS, default_fem_solver

from .base import VARIANTS, Bag, BagError, BagState, handle_dirs


def make_bag(model: str, client: int, variant: str = "front", **kw) -> Bag:
    """Build a bag model in a pybullet client.

    fem takes `solver`: "fast" (the default, config/bags.yaml: the tet mesh integrated by fem_fast,
    outside pybullet) or "bullet" (pybullet's soft body, the reference; needs a deformable-world
    client)."""
    handle_dirs(variant)   # raises BagError for an unknown variant
    solver = kw.pop("solver", None) or default_fem_solver()
    if model == "fem" and solver not in FEM_SOLVERS:
        raise BagError(f"unknown fem solver {solver!r}; known: {', '.join(FEM_SOLVERS)}")
    if model == "fem" and solver == "fast":
        from .fem_fast import FastFemBag as cls
    elif model == "fem":
        from .fem import FemBag as cls
    elif model == "constraint":
        from .constraint import ConstraintBag as cls
    elif model == "composite":
        from .composite import CompositeBag as cls
    elif model == "rigid":
        from .rigid import RigidBag as cls
    else:
        raise BagError(f"unknown bag model {model!r}; known: {', '.join(MODELS)}")
    return cls(client, variant, **kw)


__all__ = ["Bag", "BagError", "BagState", "FEM_SOLVERS", "MODELS", "VARIANTS", "handle_dirs", "make_bag"]
