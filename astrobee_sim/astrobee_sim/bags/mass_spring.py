"""Mass-spring model of the bag's tet mesh, integrated semi-implicitly for K copies at once.

The model is Bullet's deformable mass-spring (pybullet `useMassSpring`): one spring per tet edge,
force k (|d| - L) along the edge, all-direction damping c (v_j - v_i) per edge, equal node
masses. Bullet integrates it with explicit spring forces and implicit damping, solving the
damping system every step by conjugate residuals to 1e-8. Here the implicit part is a constant
matrix, mass + h c Laplacian (+ anchor springs and dampers of the grasped nodes, also implicit),
factored once with a sparse LU: a step is two sparse products, a few elementwise operations
and one pre-factored solve, the K copies being 3K right-hand sides of the same solve.

Arrays: node positions and velocities are (N, K, 3) (node, copy, axis), C-contiguous so that
reshape(N, 3K) is free. No pybullet here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu


def tet_edges(tets: np.ndarray) -> np.ndarray:
    """(E, 2) unique node pairs (i < j) of the tets' six edges."""
    t = np.asarray(tets)
    pairs = np.concatenate([t[:, [a, b]] for a, b in
                            ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))])
    pairs.sort(axis=1)
    return np.unique(pairs, axis=0)


class _DenseInverse:
    """A solve by a stored inverse (the batched path)."""

    def __init__(self, inv: np.ndarray):
        self.inv = inv

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self.inv @ b


@dataclass
class Anchors:
    """Grasped nodes: each pulled toward a target point by an implicit spring + damper."""
    nodes: np.ndarray         # (A,) node indices
    stiffness: np.ndarray     # (A,) N/m per node
    damping: np.ndarray       # (A,) N s/m per node

    def key(self) -> tuple:
        return (self.nodes.tobytes(), self.stiffness.tobytes(), self.damping.tobytes())


class MassSpring:
    """Springs on the tet edges of a mesh with `mass` spread equally over the nodes."""

    def __init__(self, nodes: np.ndarray, tets: np.ndarray, mass: float, stiffness: float,
                 damping: float):
        self.rest_nodes = np.asarray(nodes, dtype=float)
        self.n = len(self.rest_nodes)
        self.edges = tet_edges(tets)
        i, j = self.edges[:, 0], self.edges[:, 1]
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
    def elastic_forces(self, x: np.ndarray) -> np.ndarray:
        """(N, K, 3) spring forces at positions x (N, K, 3)."""
        n, k, _ = x.shape
        d = (self.B @ x.reshape(n, 3 * k)).reshape(-1, k, 3)
        length = np.sqrt(np.einsum("ekc,ekc->ek", d, d))
        s = self.stiffness * (1.0 - self.rest[:, None] / np.maximum(length, 1e-12))
        g = d * s[:, :, None]
        return -(self.Bt @ g.reshape(-1, 3 * k)).reshape(n, k, 3)

    # ---- implicit solve ------------------------------------------------------------------
    def solver(self, h: float, anchors: Anchors | None, columns: int = 3):
        """The factored matrix M + h c L + diag(h^2 ka + h ca) (cached per step and anchors).

        Few right-hand sides (one bag): a sparse LU. Many (K copies): the dense inverse, whose
        product with all 3K columns is one BLAS matrix product (several times faster than
        SuperLU's column-by-column triangular solves at K = 64)."""
        dense = columns >= 48 and self.n <= 3000
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
             external: np.ndarray | None = None) -> None:
        """One step in place: v <- solve(M v + h f(x) + anchor terms), x <- x + h v.

        target / target_vel: (A, K, 3) where each anchored node is pulled to / moves with.
        external: optional (N, K, 3) extra forces held over the step."""
        n, k, _ = x.shape
        rhs = self.elastic_forces(x)
        if external is not None:
            rhs += external
        rhs *= h
        rhs += self.node_mass * v
        if anchors is not None and len(anchors.nodes):
            idx = anchors.nodes
            rhs[idx] += h * (anchors.stiffness[:, None, None] * (target - x[idx])
                             + anchors.damping[:, None, None] * target_vel)
        v[...] = self.solver(h, anchors, 3 * k).solve(rhs.reshape(n, 3 * k)).reshape(n, k, 3)
        x += h * v

    def anchor_forces(self, x: np.ndarray, v: np.ndarray, anchors: Anchors, target: np.ndarray,
                      target_vel: np.ndarray) -> np.ndarray:
        """(A, K, 3) force each anchor spring + damper exerts on what holds it (the gripper)."""
        idx = anchors.nodes
        return (anchors.stiffness[:, None, None] * (x[idx] - target)
                + anchors.damping[:, None, None] * (v[idx] - target_vel))
