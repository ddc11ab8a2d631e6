"""Cargo-bag models sharing one interface (base.Bag): fem, constraint, composite, rigid."""
from __future__ import annotations

from .base import VARIANTS, Bag, BagError, BagState, handle_dirs

MODELS = ("fem", "constraint", "composite", "rigid")


def make_bag(model: str, client: int, variant: str = "front", **kw) -> Bag:
    """Build a bag model in a pybullet client (fem needs a deformable-world client)."""
    handle_dirs(variant)   # raises BagError for an unknown variant
    if model == "fem":
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


__all__ = ["Bag", "BagError", "BagState", "MODELS", "VARIANTS", "handle_dirs", "make_bag"]
