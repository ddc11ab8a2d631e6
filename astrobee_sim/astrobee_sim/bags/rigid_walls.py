"""Contact of K rigid boxes (the robots of batched rollouts) with the station's static wall slabs.

Same style as node_contacts (projection, inelastic normal response, Coulomb friction), for a
rigid body, vectorised over the K copies: points sampled on the box surface that are inside a
slab after a step are traced back to the face they came through (node_contacts.push_out); each
copy is translated out by its deepest point along each wall normal, and per copy and normal one
contact (the centroid of the points found with that normal: a face lying on a wall pushes at its
centre, a corner at the corner) gets the impulse that removes the inward normal velocity there,
then a friction impulse capped at mu times it. Pure numpy; a copy in open space costs nothing
beyond one bounding-box test against the slabs near the whole batch.
"""
from __future__ import annotations

import numpy as np

from . import node_contacts
from .node_contacts import grow_boxes, push_out


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross products of (M, 3) arrays (np.cross's axis handling costs ~30 us a call)."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=1)


def box_surface_points(half: np.ndarray, per_edge: int = 5) -> np.ndarray:
    """(J, 3) points on the surface of the box of half extents `half` (body frame): a grid of
    `per_edge` points along each edge (corners, edges and faces; 98 points for 5)."""
    s = np.linspace(-1.0, 1.0, int(per_edge))
    g = np.stack(np.meshgrid(s, s, s, indexing="ij"), -1).reshape(-1, 3)
    return g[(np.abs(g) == 1.0).any(axis=1)] * np.asarray(half, dtype=float)


class BoxWalls:
    """K oriented boxes on rigid bodies vs static slabs: `collide` corrects pose and twist."""

    def __init__(self, walls: np.ndarray, half: np.ndarray, offset: np.ndarray, mass: float,
                 inertia: np.ndarray, margin: float = 0.0, friction: float = 0.25,
                 per_edge: int = 5, iterations: int = 2):
        """walls (B, 6 as lo, hi); half: the box's half extents; offset: the box centre from the
        body's centre of mass (body frame); inertia: diagonal, body frame, about the COM.
        friction 0.25: Bullet's product of the default 0.5 of robot and wall."""
        self.grown = grow_boxes(np.asarray(walls, dtype=float), margin)
        self.points = box_surface_points(half, per_edge)
        self.offset = np.asarray(offset, dtype=float)
        self.half = np.asarray(half, dtype=float)
        self.radius = float(np.linalg.norm(half)) + margin
        self.inv_mass = 1.0 / float(mass)
        self.inv_inertia = 1.0 / np.asarray(inertia, dtype=float)
        self.friction, self.iterations = float(friction), int(iterations)

    def _near(self, centre: np.ndarray) -> np.ndarray:
        """Indices of the grown slabs overlapping the bounding box of every copy's sphere."""
        lo, hi = centre.min(axis=0) - self.radius, centre.max(axis=0) + self.radius
        g = self.grown
        if node_contacts._near_boxes is not None:
            return node_contacts._near_boxes(np.array([lo, hi]), g)
        return np.flatnonzero(((g[:, :3] < hi) & (g[:, 3:] > lo)).all(axis=1))

    def collide(self, pos: np.ndarray, R: np.ndarray, vel: np.ndarray, omega: np.ndarray,
                pos_prev: np.ndarray, R_prev: np.ndarray) -> np.ndarray:
        """Push K boxes (COM pos (K, 3), rotation R (K, 3, 3) body -> world, COM velocity and
        world angular velocity (K, 3)) out of the slabs, in place; pos_prev/R_prev: the pose a
        step before (which face a point came through). Returns each copy's deepest penetration
        (K,), m beyond the margin, before the correction (0 when free)."""
        k = len(pos)
        depth_out = np.zeros(k)
        centre = pos + R @ self.offset
        cand = self._near(centre)
        if not len(cand):
            return depth_out
        g = self.grown[cand]
        ext = np.abs(R) @ self.half                       # (K, 3) half extents of each box's AABB
        ov = ((g[None, :, :3] < (centre + ext)[:, None])
              & (g[None, :, 3:] > (centre - ext)[:, None])).all(axis=2)              # (K, C)
        if not ov.any():
            return depth_out
        uk = np.flatnonzero(ov.any(axis=1))               # copies near a slab
        # their surface points, one (U, J) array per axis (comparisons over a last axis of 3
        # and einsum over (U, J, 3) cost ~10x more)
        px = [centre[uk, a, None] + R[uk, a] @ self.points.T for a in range(3)]
        hits = []                                         # (copy rows, point, slab) inside
        for c in np.flatnonzero(ov.any(axis=0)):          # a few slabs
            lo, hi = g[c, :3], g[c, 3:]
            inside = ((px[0] > lo[0]) & (px[0] < hi[0]) & (px[1] > lo[1]) & (px[1] < hi[1])
                      & (px[2] > lo[2]) & (px[2] < hi[2]))
            ui, ji = np.nonzero(inside)
            if len(ui):
                hits.append((ui, ji, np.full(len(ui), c)))
        if not hits:
            return depth_out
        ui, ji, b = (np.concatenate(h) for h in zip(*hits))
        kk = uk[ui]
        q = np.stack([px[0][ui, ji], px[1][ui, ji], px[2][ui, ji]], axis=1)
        centre_prev = pos_prev[kk] + R_prev[kk] @ self.offset
        q_prev = centre_prev + (R_prev[kk] @ self.points[ji, :, None])[:, :, 0]
        ax, face = push_out(q, q_prev, g[b, :3], g[b, 3:])
        rows = np.arange(len(ui))
        depth = np.where(face == 0, q[rows, ax] - g[b, ax], g[b, 3 + ax] - q[rows, ax])
        d = ax + 3 * face                         # 0..2: normal -x,-y,-z; 3..5: +x,+y,+z
        deep = np.zeros((k, 6))
        np.maximum.at(deep, (kk, d), depth)
        csum, cnt = np.zeros((k, 6, 3)), np.zeros((k, 6))
        np.add.at(csum, (kk, d), q)
        np.add.at(cnt, (kk, d), 1.0)
        depth_out[:] = deep.max(axis=1)
        # per copy and normal one contact: the centroid of its points (arm from the COM)
        dirs = np.flatnonzero(cnt.any(axis=0))
        arms = []
        for dd in dirs:
            c = np.flatnonzero(cnt[:, dd])
            arms.append((dd, c, csum[c, dd] / cnt[c, dd, None] - pos[c]))
        # position: out along each normal by the deepest point (walls do not face each other
        # within a box's width, so opposite normals never both occur in practice)
        pos += deep[:, 3:] - deep[:, :3]
        # velocity: inelastic normal impulses, sequential over the normals, then friction
        acc = np.zeros((k, 6))
        normals = np.concatenate([-np.eye(3), np.eye(3)])
        for it in range(self.iterations + 1):
            for dd, c, r in arms:
                n = normals[dd]
                v_c = vel[c] + _cross(omega[c], r)
                if it < self.iterations:                                # normal impulses
                    kn = self._eff_mass(R[c], r, np.broadcast_to(n, r.shape))
                    new = np.maximum(acc[c, dd] - (v_c @ n) / kn, 0.0)
                    j = (new - acc[c, dd])[:, None] * n
                    acc[c, dd] = new
                else:                                                   # friction, once
                    vt = v_c - (v_c @ n)[:, None] * n
                    tn = np.linalg.norm(vt, axis=1)
                    t = vt / np.maximum(tn, 1e-300)[:, None]
                    jt = np.minimum(tn / self._eff_mass(R[c], r, t), self.friction * acc[c, dd])
                    j = -jt[:, None] * t
                vel[c] += self.inv_mass * j
                omega[c] += self._inv_inertia_world(R[c], _cross(r, j))
        return depth_out

    def _inv_inertia_world(self, R: np.ndarray, L: np.ndarray) -> np.ndarray:
        """World-frame I^-1 L for rotations R (M, 3, 3) and vectors L (M, 3)."""
        return np.einsum("mij,mj->mi", R, self.inv_inertia * np.einsum("mji,mj->mi", R, L))

    def _eff_mass(self, R: np.ndarray, r: np.ndarray, n: np.ndarray) -> np.ndarray:
        """1/m + n . ((I^-1 (r x n)) x r): the inverse effective mass along n at arm r."""
        a = self._inv_inertia_world(R, _cross(r, n))
        return self.inv_mass + np.einsum("mi,mi->m", n, _cross(a, r))
