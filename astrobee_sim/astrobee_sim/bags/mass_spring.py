"""Mass-spring model of the bag's tet mesh, integrated semi-implicitly for K copies at once.

The model is what pybullet 3.2.7 builds for our VTK soft body (`loadSoftBody(useMassSpring=1)`,
read in bullet3's PhysicsServerCommandProcessor.cpp and btDeformableMassSpringForce.h): one
spring per tet edge, force k (|d| - L) along the edge; "bending" springs between nodes two edges
apart (btSoftBody::generateBendingConstraints(2), stiffness springBendingStiffness, 0.1 N/m by
default); damping c along each spring only, c ((v_j - v_i) . u) u on every spring, bending ones
included (for a VTK file pybullet constructs the force with momentum_conserving = true: our
`springDampingAllDirections=1` is ignored); equal node masses. Bullet evaluates the spring forces
explicitly at the predicted positions x + h v and the damping implicitly, solving the damping
system every step by conjugate residuals.

Here the implicit part is split so that its matrix stays constant: M + h c L (L the Laplacian of
all springs: damping in all directions) plus the grasped nodes' implicit anchor springs and
dampers, factored once with a sparse LU; the damping across the springs, which Bullet does not
have, is taken back explicitly, h c B^T (I - u u^T) B v with the velocities of the last
iterate (`damping_iterations` solves per step, 1 by default). A step is a few sparse products,
elementwise operations and one pre-factored solve per iteration, the K copies being 3K
right-hand sides of the same solve.

The per-edge work (spring forces at x + h v, the cross-damping correction, the scatter onto the
nodes) is one numba loop when numba is installed (~4x less than the sparse products and ~10
whole-array numpy operations it replaces, the same sums to 1e-15), else numpy; so is the grasp's
work on the held nodes (tethers, the strap's twist spring, the tethers' low-rank solve:
hold_kernels).

Arrays: node positions and velocities are (N, K, 3) (node, copy, axis), C-contiguous so that
reshape(N, 3K) is free. No pybullet here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from . import hold_kernels
from ..grasp import twist_forces, twist_weights

try:
    from numba import njit
except ImportError:          # numba missing: the numpy path below
    njit = None


def _edge_forces_loop(x, v, ei, ej, rest, ke, c, h, across):  # pragma: no cover - compiled
    """(N, K, 3) node forces of the springs at x + h v, minus c (I - u u^T)(v_j - v_i) when
    `across` (u the spring direction at x): MassSpring.step's right-hand side, in one pass."""
    n, k, _ = x.shape
    out = np.zeros((n, k, 3))
    for e in range(ei.shape[0]):
        i, j = ei[e], ej[e]
        for b in range(k):
            d0, d1, d2 = x[j, b, 0] - x[i, b, 0], x[j, b, 1] - x[i, b, 1], x[j, b, 2] - x[i, b, 2]
            w0, w1, w2 = v[j, b, 0] - v[i, b, 0], v[j, b, 1] - v[i, b, 1], v[j, b, 2] - v[i, b, 2]
            q0, q1, q2 = d0 + h * w0, d1 + h * w1, d2 + h * w2
            s = ke[e] * (1.0 - rest[e] / max(np.sqrt(q0 * q0 + q1 * q1 + q2 * q2), 1e-12))
            g0, g1, g2 = q0 * s, q1 * s, q2 * s
            if across:
                ln = max(np.sqrt(d0 * d0 + d1 * d1 + d2 * d2), 1e-12)
                u0, u1, u2 = d0 / ln, d1 / ln, d2 / ln
                a = u0 * w0 + u1 * w1 + u2 * w2
                g0 -= c * (w0 - u0 * a)
                g1 -= c * (w1 - u1 * a)
                g2 -= c * (w2 - u2 * a)
            out[i, b, 0] += g0
            out[i, b, 1] += g1
            out[i, b, 2] += g2
            out[j, b, 0] -= g0
            out[j, b, 1] -= g1
            out[j, b, 2] -= g2
    return out


_edge_forces_compiled = njit(cache=True)(_edge_forces_loop) if njit is not None else None
_warm = False


def warm_up() -> None:
    """Load (or compile, the first time on a machine) the numba loops now, ~0.5-1.5 s once per
    process, rather than inside the first step of a timed or lockstep run."""
    global _warm
    if _warm or _edge_forces_compiled is None:
        return
    z = np.zeros((2, 1, 3))
    _edge_forces_compiled(z, z, np.zeros(1, np.int64), np.ones(1, np.int64), np.ones(1),
                          np.ones(1), 0.1, 0.01, True)
    from .node_contacts import _near_boxes
    if _near_boxes is not None:
        _near_boxes(np.zeros((2, 3)), np.zeros((1, 6)))
    hold_kernels.warm_up()
    _warm = True


def tet_edges(tets: np.ndarray) -> np.ndarray:
    """(E, 2) unique node pairs (i < j) of the tets' six edges."""
    t = np.asarray(tets)
    pairs = np.concatenate([t[:, [a, b]] for a, b in
                            ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))])
    pairs.sort(axis=1)
    return np.unique(pairs, axis=0)


def second_neighbour_pairs(edges: np.ndarray, n: int) -> np.ndarray:
    """(E2, 2) node pairs (i < j) two edges apart and not joined by an edge (Bullet's bending
    springs, generateBendingConstraints(2))."""
    a = sp.csr_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    a = ((a + a.T) > 0).astype(np.int32)
    two = ((a @ a) > 0).astype(np.int32) - a
    two = sp.triu(two, k=1).tocoo()
    keep = two.data > 0
    return np.stack([two.row[keep], two.col[keep]], axis=1).astype(edges.dtype)


class _DenseInverse:
    """A solve by a stored inverse (the batched path)."""

    def __init__(self, inv: np.ndarray):
        self.inv = inv

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self.inv @ b


class _LowRank:
    """A solve with (A0 + W^T D W): A0 pre-factored, W (G, N) the tethers' averaging rows, D
    their (h^2 K + h C); the Woodbury identity keeps A0's factor (no fill-in from the groups'
    dense blocks). The group sums are gathers over the few group nodes and the correction is
    elementwise, so each copy's columns see the same arithmetic (equal copies stay equal)."""

    def __init__(self, base, groups: list, w: np.ndarray, d: np.ndarray, compiled: bool = True):
        self.base, self.groups, self.w = base, [np.asarray(g) for g in groups], w
        self.z = np.ascontiguousarray(base.solve(np.ascontiguousarray(w.T)))   # (N, G)
        self.s = np.linalg.inv(np.diag(1.0 / d) + w @ self.z)               # (G, G)
        self.packed = hold_kernels.pack_groups(self.groups)
        self.compiled = compiled and hold_kernels.lowrank_update is not None

    def solve(self, b: np.ndarray) -> np.ndarray:
        y = self.base.solve(b)
        if self.compiled:                       # one pass over the group nodes and the columns
            hold_kernels.lowrank_update(y, self.z, self.s, *self.packed)
            return y
        if y.shape[1] <= 3:                     # one copy: BLAS (no copies to keep equal)
            return y - self.z @ (self.s @ (self.w @ y))
        t = [y[g].mean(axis=0) for g in self.groups]
        for i in range(len(self.groups)):
            c = self.s[i, 0] * t[0]
            for j in range(1, len(t)):
                c = c + self.s[i, j] * t[j]
            y -= self.z[:, i:i + 1] * c
        return y


def _means(groups: list, y: np.ndarray) -> np.ndarray:
    """(G, K, 3) centroids of y (N, K, 3) over each node group (gathers: cheap, and equal
    copies summed alike)."""
    return np.stack([y[g].mean(axis=0) for g in groups])


_NO_GROUPS = (np.zeros(0, np.int64), np.zeros(1, np.int64), np.zeros(0), np.zeros(0))
_NO_TWISTS = _NO_GROUPS


@dataclass
class Anchors:
    """Grasped nodes: each pulled toward a target point by an implicit spring + damper."""
    nodes: np.ndarray         # (A,) node indices
    stiffness: np.ndarray     # (A,) N/m per node
    damping: np.ndarray       # (A,) N s/m per node

    def key(self) -> tuple:
        return (self.nodes.tobytes(), self.stiffness.tobytes(), self.damping.tobytes())


@dataclass
class Tethers:
    """Node groups each held by its centroid: an implicit spring + damper pulls the group's mean
    position toward a target point, the force spread equally over the group (a ball joint at the
    centroid that leaves the group free to turn about it; astrobee_sim.grasp's strap and hinge)."""
    groups: list              # G arrays of node indices
    stiffness: np.ndarray     # (G,) N/m per group
    damping: np.ndarray       # (G,) N s/m per group

    def key(self) -> tuple:
        return (tuple(np.asarray(g).tobytes() for g in self.groups), self.stiffness.tobytes(),
                self.damping.tobytes())

    def weights(self, n: int) -> np.ndarray:
        """(G, n) averaging rows: row i is 1/len(group i) on the group's nodes (one matrix
        product takes every centroid; its transpose spreads a force over the group)."""
        w = getattr(self, "_w", None)
        if w is None or w.shape[1] != n:
            w = np.zeros((len(self.groups), n))
            for i, g in enumerate(self.groups):
                w[i, np.asarray(g)] = 1.0 / len(g)
            self._w = w
        return w

    def packed(self) -> tuple:
        """(nodes, ptr, stiffness, damping) as the compiled loops take them (cached)."""
        if getattr(self, "_packed", None) is None:
            self._packed = (*hold_kernels.pack_groups(self.groups),
                            np.ascontiguousarray(self.stiffness, dtype=float),
                            np.ascontiguousarray(self.damping, dtype=float))
        return self._packed


@dataclass
class Twists:
    """The strap's twist springs (astrobee_sim.grasp.twist_forces), one per held handle: a
    torque about the handle normal between the strap's two halves (node groups a and b),
    -(k angle + c rate) n, as a force on a's centroid and its opposite on b's. The holder
    gives each step the frames (T, K, 9): the normal n, the strap's rest long axis u (both
    carried by the gripper) and the gripper's angular velocity."""
    halves: list              # T pairs (a, b) of node index arrays
    stiffness: np.ndarray     # (T,) N m/rad
    damping: np.ndarray       # (T,) N m s/rad

    def packed(self) -> tuple:
        """(nodes, ptr, stiffness, damping): groups 2t and 2t + 1 are twist t's halves."""
        if getattr(self, "_packed", None) is None:
            self._packed = (*hold_kernels.pack_groups([g for ab in self.halves for g in ab]),
                            np.ascontiguousarray(self.stiffness, dtype=float),
                            np.ascontiguousarray(self.damping, dtype=float))
        return self._packed

    def numpy_forces(self, x: np.ndarray, v: np.ndarray, frames: np.ndarray) -> list:
        """Per twist: (weights (N,), force on a's centroid (K, 3), torque on the gripper (K, 3)),
        by grasp.twist_forces (the path without numba)."""
        out = []
        for t, (a, b) in enumerate(self.halves):
            w = twist_weights(len(x), a, b)
            fa, tau = twist_forces(x, v, w, frames[t, :, 0:3], frames[t, :, 3:6],
                                   frames[t, :, 6:9], float(self.stiffness[t]),
                                   float(self.damping[t]))
            out.append((w, fa, tau))
        return out


class MassSpring:
    """Springs on the tet edges of a mesh (+ Bullet's bending springs) with `mass` spread
    equally over the nodes; damping along the springs ("spring", Bullet's) or in all
    directions ("all", a constant matrix, no explicit correction)."""

    def __init__(self, nodes: np.ndarray, tets: np.ndarray, mass: float, stiffness: float,
                 damping: float, bending_stiffness: float = 0.0, damping_mode: str = "spring",
                 damping_iterations: int = 1):
        if damping_mode not in ("spring", "all"):
            raise ValueError(f"damping_mode must be 'spring' or 'all', got {damping_mode!r}")
        self.rest_nodes = np.asarray(nodes, dtype=float)
        self.n = len(self.rest_nodes)
        edges = tet_edges(tets)
        self.num_tet_edges = len(edges)
        if bending_stiffness > 0:     # Bullet generates bending springs only for a stiffness > 0
            edges = np.concatenate([edges, second_neighbour_pairs(edges, self.n)])
        self.edges = edges
        self.edge_stiffness = np.full(len(edges), float(stiffness))
        self.edge_stiffness[self.num_tet_edges:] = float(bending_stiffness)
        self.damping_mode = damping_mode
        self.damping_iterations = max(1, int(damping_iterations))
        i, j = self.edges[:, 0], self.edges[:, 1]
        self._ei = np.ascontiguousarray(i, dtype=np.int64)
        self._ej = np.ascontiguousarray(j, dtype=np.int64)
        self.use_numba = _edge_forces_compiled is not None
        warm_up()
        self.rest = np.linalg.norm(self.rest_nodes[j] - self.rest_nodes[i], axis=1)
        e = len(self.edges)
        rows = np.repeat(np.arange(e), 2)
        cols = self.edges.reshape(-1)
        vals = np.tile([-1.0, 1.0], e)
        self.B = sp.csr_matrix((vals, (rows, cols)), shape=(e, self.n))   # d = B x = x_j - x_i
        self.Bt = self.B.T.tocsr()
        self.laplacian = (self.Bt @ self.B).tocsc()
        self.node_mass = float(mass) / self.n
        self.stiffness = float(stiffness)
        self.damping = float(damping)
        self._lu: dict = {}

    # ---- forces --------------------------------------------------------------------------
    def _edge_vectors(self, y: np.ndarray) -> np.ndarray:
        n, k, _ = y.shape
        return (self.B @ y.reshape(n, 3 * k)).reshape(-1, k, 3)

    def _to_nodes(self, g: np.ndarray) -> np.ndarray:
        """(N, K, 3) node forces of per-edge forces g (E, K, 3) acting on each edge's j node."""
        k = g.shape[1]
        return -(self.Bt @ g.reshape(-1, 3 * k)).reshape(self.n, k, 3)

    def _spring_edge_forces(self, d: np.ndarray) -> np.ndarray:
        length = np.sqrt(np.einsum("ekc,ekc->ek", d, d))
        s = self.edge_stiffness[:, None] * (1.0 - self.rest[:, None] / np.maximum(length, 1e-12))
        return d * s[:, :, None]

    def elastic_forces(self, x: np.ndarray) -> np.ndarray:
        """(N, K, 3) spring forces at positions x (N, K, 3)."""
        return self._to_nodes(self._spring_edge_forces(self._edge_vectors(x)))

    def _cross_damping(self, u: np.ndarray, dv: np.ndarray) -> np.ndarray:
        """Per-edge c (I - u u^T) dv: the damping across the springs (u unit edge directions)."""
        along = np.einsum("ekc,ekc->ek", u, dv)
        return self.damping * (dv - u * along[:, :, None])

    # ---- implicit solve ------------------------------------------------------------------
    def solver(self, h: float, anchors: Anchors | None, columns: int = 3,
               tethers: Tethers | None = None):
        """The factored matrix M + h c L + diag(h^2 ka + h ca) + the tethers' blocks
        (h^2 K + h C) / n^2 over each group's n x n nodes (cached per step, anchors, tethers;
        the tethers by a low-rank update of the factor without them).

        Few right-hand sides (one bag): a sparse LU. Many (K copies): the dense inverse, whose
        product with all 3K columns is one BLAS matrix product (several times faster than
        SuperLU's column-by-column triangular solves at K = 64)."""
        dense = columns >= 48 and self.n <= 3000
        if tethers is not None and len(tethers.groups):
            key = (h, None if anchors is None else anchors.key(), dense, tethers.key(),
                   self.use_numba)
            lu = self._lu.get(key)
            if lu is None:
                lu = _LowRank(self.solver(h, anchors, columns), tethers.groups,
                              tethers.weights(self.n),
                              h * h * tethers.stiffness + h * tethers.damping, self.use_numba)
                self._lu[key] = lu
            return lu
        key = (h, None if anchors is None else anchors.key(), dense)
        lu = self._lu.get(key)
        if lu is None:
            diag = np.full(self.n, self.node_mass)
            if anchors is not None and len(anchors.nodes):
                np.add.at(diag, anchors.nodes, h * h * anchors.stiffness + h * anchors.damping)
            a = (sp.diags(diag) + (h * self.damping) * self.laplacian).tocsc()
            if dense:
                lu = _DenseInverse(np.linalg.inv(a.toarray()))
            else:
                lu = splu(a, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                          options={"SymmetricMode": True})
            if len(self._lu) > 16:
                self._lu.clear()
            self._lu[key] = lu
        return lu

    def step(self, x: np.ndarray, v: np.ndarray, h: float, anchors: Anchors | None = None,
             target: np.ndarray | None = None, target_vel: np.ndarray | None = None,
             external: np.ndarray | None = None, tethers: Tethers | None = None,
             tether_target: np.ndarray | None = None,
             tether_vel: np.ndarray | None = None, twists: Twists | None = None,
             twist_frames: np.ndarray | None = None) -> np.ndarray | None:
        """One step in place: v <- solve(M v + h f(x) + anchor terms), x <- x + h v.

        target / target_vel: (A, K, 3) where each anchored node is pulled to / moves with.
        external: optional (N, K, 3) extra forces held over the step.
        tethers: node groups held by their centroids at tether_target / tether_vel (G, K, 3).
        twists: the strap's twist springs, with their frames (T, K, 9) (Twists).
        Returns the twist springs' torques on the grippers (T, K, 3), or None without twists."""
        n, k, _ = x.shape
        across = self.damping_mode == "spring" and self.damping > 0
        u = None
        if self.use_numba and (not across or self.damping_iterations == 1):
            rhs = _edge_forces_compiled(x, v, self._ei, self._ej, self.rest, self.edge_stiffness,
                                        self.damping, h, across)
        else:
            dx = self._edge_vectors(x)
            dv = self._edge_vectors(v)
            g = self._spring_edge_forces(dx + h * dv)      # at the predicted x + h v, as Bullet
            if across:
                u = dx / np.maximum(np.sqrt(np.einsum("ekc,ekc->ek", dx, dx)), 1e-12)[:, :, None]
                g -= self._cross_damping(u, dv)             # c (I - uu^T) dv, taken back
            rhs = self._to_nodes(g)
        if external is not None:
            rhs += external
        rhs *= h
        rhs += self.node_mass * v
        if anchors is not None and len(anchors.nodes):
            idx = anchors.nodes
            rhs[idx] += h * (anchors.stiffness[:, None, None] * (target - x[idx])
                             + anchors.damping[:, None, None] * target_vel)
        twist_tau = self._hold_rhs(rhs, x, v, h, tethers, tether_target, tether_vel, twists,
                                   twist_frames)
        lu = self.solver(h, anchors, 3 * k, tethers)
        new = lu.solve(rhs.reshape(n, 3 * k)).reshape(n, k, 3)
        if u is not None and self.damping_iterations > 1:
            base = rhs + h * self._to_nodes(self._cross_damping(u, dv))   # without the correction
            for _ in range(self.damping_iterations - 1):
                corr = base - h * self._to_nodes(self._cross_damping(u, self._edge_vectors(new)))
                new = lu.solve(corr.reshape(n, 3 * k)).reshape(n, k, 3)
        v[...] = new
        x += h * v
        return twist_tau

    def _hold_rhs(self, rhs, x, v, h, tethers, tether_target, tether_vel, twists,
                  twist_frames) -> np.ndarray | None:
        """Adds the tethers' explicit spring terms and the twist springs' forces (times h) to
        rhs; returns the twist torques on the grippers (T, K, 3) or None."""
        if tethers is None and twists is None:
            return None
        k = x.shape[1]
        if self.use_numba:
            gn, gp, gk, gc = tethers.packed() if tethers is not None else _NO_GROUPS
            tt = tv = np.zeros((0, k, 3))
            if tethers is not None:
                tt, tv = tether_target, tether_vel
            wn, wp, wk, wc = twists.packed() if twists is not None else _NO_TWISTS
            fr = twist_frames if twists is not None else np.zeros((0, k, 9))
            tau = hold_kernels.hold_rhs(rhs, x, v, h, gn, gp, gk, gc, tt, tv, wn, wp, wk, wc, fr)
            return tau if twists is not None else None
        if tethers is not None:
            f = (tethers.stiffness[:, None, None] * (tether_target - _means(tethers.groups, x))
                 + tethers.damping[:, None, None] * tether_vel)
            for i, g in enumerate(tethers.groups):
                rhs[g] += (h / len(g)) * f[i]
        if twists is None:
            return None
        taus = []
        for w, fa, tau in twists.numpy_forces(x, v, twist_frames):
            rhs += (h * w)[:, None, None] * fa[None]
            taus.append(tau)
        return np.stack(taus)

    def anchor_forces(self, x: np.ndarray, v: np.ndarray, anchors: Anchors, target: np.ndarray,
                      target_vel: np.ndarray) -> np.ndarray:
        """(A, K, 3) force each anchor spring + damper exerts on what holds it (the gripper)."""
        idx = anchors.nodes
        return (anchors.stiffness[:, None, None] * (x[idx] - target)
                + anchors.damping[:, None, None] * (v[idx] - target_vel))

    def tether_forces(self, x: np.ndarray, v: np.ndarray, tethers: Tethers, target: np.ndarray,
                      target_vel: np.ndarray) -> np.ndarray:
        """(G, K, 3) force each tether exerts on what holds it (the gripper)."""
        if self.use_numba:
            return hold_kernels.tether_pull(x, v, *tethers.packed(), target, target_vel)
        xm, vm = _means(tethers.groups, x), _means(tethers.groups, v)
        return (tethers.stiffness[:, None, None] * (xm - target)
                + tethers.damping[:, None, None] * (vm - target_vel))
