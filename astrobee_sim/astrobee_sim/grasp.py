"""How a bag's handle follows the gripper: the grasp models, one registry (`GRASPS`).

    strap  the handle is a short webbing strap (the default): the bag pivots freely about the
           grasp point in two axes (a ball joint) with a weak twist spring about the handle's
           normal; the strap itself is stiff (config/bags.yaml grasp.models.strap);
    hinge  the seed's grasp: held at two points on one line along the strap, ~+-5 cm about the
           grasp point, so the bag turns about the strap's long axis only;
    clamp  the handle's whole outer patch tied to the gripper (robot and bag one rigid body).

Each model says, for every bag fidelity, which points are tied and how: `fem_hold` for the fast
FEM solver (per-node springs, centroid springs on node groups, the twist spring), `bullet_nodes`
for pybullet's soft-body anchors, `joints` for the rigid-part bags (point-to-point or fixed
constraints + the twist spring). Figures are assumptions (docs/grasp.md), scaled by the realism
knob handle_stiffness_scale.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from astrobee import config


class GraspError(ValueError):
    """An unknown grasp model name."""


@dataclass(frozen=True)
class GraspFigures:
    """A grasp's figures: translational stiffness / damping of the hold (N/m, N s/m, total per
    handle), twist spring (N m/rad, N m s/rad) and the hinge's half span (m)."""
    stiffness: float = 5000.0
    damping: float = 20.0
    twist_stiffness: float = 0.0
    twist_damping: float = 0.0
    half_span: float = 0.05

    def scaled(self, s: float) -> "GraspFigures":
        """handle_stiffness_scale: the stiffnesses times s (dampings kept)."""
        return replace(self, stiffness=self.stiffness * s, twist_stiffness=self.twist_stiffness * s)


@dataclass
class FemHold:
    """One handle's hold in the fast FEM solver (node indices into the bag mesh)."""
    anchors: np.ndarray                  # (A,) nodes each tied to its own point (clamp)
    anchor_stiffness: float              # N/m per node
    anchor_damping: float
    tethers: list[np.ndarray]            # node groups whose centroid is tied to a point
    tether_stiffness: float              # N/m per group
    tether_damping: float
    twist: tuple[np.ndarray, np.ndarray] | None = None   # two node groups spanning the strap
    twist_stiffness: float = 0.0
    twist_damping: float = 0.0


@dataclass(frozen=True)
class Joint:
    """A rigid-part bag's tie: point-to-point constraints at offsets (bag frame, from the handle
    point) sharing the handle's force budget, or one fixed constraint."""
    points: tuple[tuple[float, float, float], ...]
    fixed: bool = False
    twist_stiffness: float = 0.0
    twist_damping: float = 0.0


def strap_axis(size, handle_dir) -> np.ndarray:
    """Unit long axis of a handle's strap in the bag frame (the face's longer side, as mesh.py)."""
    h = np.asarray(handle_dir, dtype=float)
    ax = int(np.argmax(np.abs(h)))
    tang = [a for a in range(3) if a != ax]
    long_ax = sorted(tang, key=lambda a: -float(np.asarray(size)[a]))[0]
    return np.eye(3)[long_ax]


class Grasp:
    """A grasp model with its figures (see the module docstring)."""
    name = "base"

    def __init__(self, figures: GraspFigures):
        self.figures = figures

    def fem_hold(self, rest: np.ndarray, handle: np.ndarray, centre: np.ndarray,
                 axis: np.ndarray) -> FemHold:
        """rest: mesh nodes (bag frame); handle: the handle's outer nodes; centre: the grasp
        point; axis: the strap's long axis."""
        raise NotImplementedError

    def bullet_nodes(self, rest: np.ndarray, handle: np.ndarray, centre: np.ndarray,
                     axis: np.ndarray) -> list[int]:
        """Nodes pinned to the gripper by pybullet soft-body anchors (rigid pins)."""
        raise NotImplementedError

    def joint(self, axis: np.ndarray) -> Joint:
        raise NotImplementedError


GRASPS: dict[str, type[Grasp]] = {}


def register(cls: type[Grasp]) -> type[Grasp]:
    GRASPS[cls.name] = cls
    return cls


def _nearest(rest: np.ndarray, handle: np.ndarray, point: np.ndarray) -> int:
    return int(handle[np.argmin(np.linalg.norm(rest[handle] - point, axis=1))])


def _halves(rest: np.ndarray, handle: np.ndarray, centre: np.ndarray,
            axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The handle's nodes on either side of the grasp point along the strap's long axis (the
    nodes on the plane through it belong to neither half)."""
    s = (rest[handle] - centre) @ axis
    return handle[s > 1e-9], handle[s < -1e-9]


@register
class Strap(Grasp):
    """Ball joint at the grasp point (the handle patch's centroid tied to it) + twist spring."""
    name = "strap"

    def fem_hold(self, rest, handle, centre, axis):
        f = self.figures
        a, b = _halves(rest, handle, centre, axis)
        twist = (a, b) if len(a) and len(b) and f.twist_stiffness + f.twist_damping > 0 else None
        return FemHold(np.zeros(0, int), 0.0, 0.0, [np.asarray(handle)], f.stiffness, f.damping,
                       twist, f.twist_stiffness, f.twist_damping)

    def bullet_nodes(self, rest, handle, centre, axis):
        return [_nearest(rest, handle, centre)]

    def joint(self, axis):
        f = self.figures
        return Joint(((0.0, 0.0, 0.0),), False, f.twist_stiffness, f.twist_damping)


@register
class Hinge(Grasp):
    """Two points on the strap's long axis, +-half_span about the grasp point (the seed's)."""
    name = "hinge"

    def fem_hold(self, rest, handle, centre, axis):
        f = self.figures
        groups = list(_halves(rest, handle, centre, axis))
        if not all(len(g) for g in groups):           # a handle one node long: a ball joint
            groups = [np.asarray(handle)]
        return FemHold(np.zeros(0, int), 0.0, 0.0, groups, f.stiffness / len(groups),
                       f.damping / len(groups))

    def bullet_nodes(self, rest, handle, centre, axis):
        d = self.figures.half_span * axis
        nodes = [_nearest(rest, handle, centre + d), _nearest(rest, handle, centre - d)]
        return sorted(set(nodes))

    def joint(self, axis):
        d = self.figures.half_span * np.asarray(axis, dtype=float)
        return Joint((tuple(d), tuple(-d)))


@register
class Clamp(Grasp):
    """Every outer handle node tied to its own point on the gripper (the grasp before round 4)."""
    name = "clamp"

    def fem_hold(self, rest, handle, centre, axis):
        f = self.figures
        n = max(len(handle), 1)
        return FemHold(np.asarray(handle, dtype=int), f.stiffness / n, f.damping / n, [], 0.0, 0.0)

    def bullet_nodes(self, rest, handle, centre, axis):
        return [int(i) for i in handle]

    def joint(self, axis):
        return Joint(((0.0, 0.0, 0.0),), fixed=True)


def grasp_table() -> dict:
    """config/bags.yaml's `grasp:` section (default name and each model's figures)."""
    return dict(config.bags().get("grasp") or {})


def default_grasp() -> str:
    return str(grasp_table().get("default", "strap"))


def check_grasp(name: str) -> str:
    if name not in GRASPS:
        raise GraspError(f"unknown grasp {name!r}; known: {', '.join(GRASPS)}")
    return name


def make_grasp(name: str | None = None, handle_stiffness_scale: float = 1.0, **figures) -> Grasp:
    """The grasp model `name` (None: bags.yaml's default) with its bags.yaml figures, any given
    `figures` replacing them, stiffnesses times handle_stiffness_scale."""
    name = check_grasp(name or default_grasp())
    base = dict((grasp_table().get("models") or {}).get(name) or {})
    base.update({k: v for k, v in figures.items() if v is not None})
    known = set(GraspFigures.__dataclass_fields__)
    fig = GraspFigures(**{k: float(v) for k, v in base.items() if k in known})
    return GRASPS[name](fig.scaled(float(handle_stiffness_scale)))


def twist_weights(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n,) weights whose product with the nodes is the strap's span: mean(a) - mean(b); the
    same weights spread a force on a's centroid (and its opposite on b's) over the nodes."""
    w = np.zeros(n)
    w[np.asarray(a)] = 1.0 / len(a)
    w[np.asarray(b)] = -1.0 / len(b)
    return w


def twist_forces(x: np.ndarray, v: np.ndarray, w: np.ndarray, n: np.ndarray, u: np.ndarray,
                 w_grip: np.ndarray, k: float, c: float):
    """The twist spring on K copies: x, v (N, K, 3); w the strap's twist_weights; n (K, 3)
    the handle normal and u (K, 3) the strap's rest long axis, both carried by the gripper;
    w_grip (K, 3) the gripper's angular velocity. The twist is the angle of the strap's current
    span (projected on the plane normal to n) from u about n: torque -(k angle + c rate) n.

    Returns (fa, torque_on_gripper), both (K, 3): fa the force on the span's first group's
    centroid (spread over the nodes as w[:, None, None] * fa; the second group gets -fa).
    The fast FEM bag runs the same formulas compiled (bags/hold_kernels.py) when numba is
    installed; this is the numpy path and the batched rollouts'."""
    pos, neg = np.flatnonzero(w > 0), np.flatnonzero(w < 0)   # gathers: copies summed alike
    e = x[pos].mean(axis=0) - x[neg].mean(axis=0)
    de = v[pos].mean(axis=0) - v[neg].mean(axis=0)
    ep = e - np.einsum("kc,kc->k", e, n)[:, None] * n
    ang = np.arctan2(np.einsum("kc,kc->k", np.cross(u, ep), n), np.einsum("kc,kc->k", u, ep))
    e2 = np.maximum(np.einsum("kc,kc->k", e, e), 1e-12)
    rate = np.einsum("kc,kc->k", np.cross(e, de), n) / e2 - np.einsum("kc,kc->k", w_grip, n)
    tau = -(k * ang + c * rate)
    fa = (tau / e2)[:, None] * np.cross(n, e)
    return fa, -np.cross(e, fa)
