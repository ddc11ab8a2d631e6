"""Cargo-bag models sharing one interface (base.Bag): fem, constraint, composite, rigid."""
from __future__ import annotations

from astrobee.overrides import BAG_MODELS as MODELS
from astrobee.overrides import FEM_SOLVERS
from astrobee.scenario import default_fem_solver

from .base import VARIANTS, Bag, BagError, BagState, handle_dirs


# model (fem: "fem/<solver>") -> "module:class", imported when first built
BAG_CLASSES: dict[str, str] = {
    "fem/fast": "fem_fast:FastFemBag",
    "fem/bullet": "fem:FemBag",
    "constraint": "constraint:ConstraintBag",
    "composite": "composite:CompositeBag",
    "rigid": "rigid:RigidBag",
}


def make_bag(model: str, client: int, variant: str = "front", **kw) -> Bag:
    """Build a bag model in a pybullet client (BAG_CLASSES; BagError for an unknown model,
    variant, solver or grasp).

    fem takes `solver`: "fast" (the default, config/bags.yaml: the tet mesh integrated by fem_fast,
    outside pybullet) or "bullet" (pybullet's soft body, the reference; needs a deformable-world
    client). Every model takes `grasp` (astrobee_sim.grasp) and `handle_stiffness_scale`."""
    import importlib
    handle_dirs(variant)   # raises BagError for an unknown variant
    solver = kw.pop("solver", None) or default_fem_solver()
    if model == "fem" and solver not in FEM_SOLVERS:
        raise BagError(f"unknown fem solver {solver!r}; known: {', '.join(FEM_SOLVERS)}")
    key = f"fem/{solver}" if model == "fem" else model
    if key not in BAG_CLASSES:
        raise BagError(f"unknown bag model {model!r}; known: {', '.join(MODELS)}")
    module, name = BAG_CLASSES[key].split(":")
    cls = getattr(importlib.import_module(f".{module}", __name__), name)
    return cls(client, variant, **kw)


__all__ = ["BAG_CLASSES", "Bag", "BagError", "BagState", "FEM_SOLVERS", "MODELS", "VARIANTS", "handle_dirs", "make_bag"]
