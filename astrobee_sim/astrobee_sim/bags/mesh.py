"""Tetrahedral mesh of a cargo bag: a box body plus handle blocks, written as a tets-only VTK.

A structured grid (one extra layer of cells beyond each handle face) is split into 6 tets per hex
(Kuhn subdivision: the same diagonal in every cell, so neighbouring cells share faces exactly);
the body cells and the handle cells at the centre of each handle face are kept. Every tet is
positively oriented (det > 0), which pybullet's deformable solver needs to stay stable.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations

import numpy as np

# Kuhn subdivision of the unit cube: one tet per permutation of the axes along the 0->7 diagonal.
_CORNER = {(i, j, k): i + 2 * j + 4 * k for i in (0, 1) for j in (0, 1) for k in (0, 1)}


def _kuhn_tets() -> list[list[int]]:
    tets = []
    for perm in permutations(range(3)):
        c = [0, 0, 0]
        t = [_CORNER[tuple(c)]]
        for ax in perm:
            c[ax] = 1
            t.append(_CORNER[tuple(c)])
        tets.append(t)
    return tets


KUHN = _kuhn_tets()


@dataclass
class TetMesh:
    nodes: np.ndarray        # (N, 3) rest positions, bag frame (origin at the box centre)
    tets: np.ndarray         # (T, 4) node indices, positively oriented
    handle_nodes: list[np.ndarray]   # per handle: indices of the outermost handle nodes

    def volumes(self) -> np.ndarray:
        a, b, c, d = (self.nodes[self.tets[:, i]] for i in range(4))
        return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0

    def write_vtk(self, path: str) -> None:
        """Legacy ASCII VTK unstructured grid holding tetrahedra only (cell type 10)."""
        lines = ["# vtk DataFile Version 2.0", "astrobee cargo bag", "ASCII",
                 "DATASET UNSTRUCTURED_GRID", f"POINTS {len(self.nodes)} double"]
        lines += [f"{x:.9g} {y:.9g} {z:.9g}" for x, y, z in self.nodes]
        lines.append(f"CELLS {len(self.tets)} {5 * len(self.tets)}")
        lines += [f"4 {a} {b} {c} {d}" for a, b, c, d in self.tets]
        lines.append(f"CELL_TYPES {len(self.tets)}")
        lines += ["10"] * len(self.tets)
        with open(path, "w") as f:
            f.write("\n".join(lines) + "\n")


def _spacing(size: np.ndarray, nodes: int) -> np.ndarray:
    """Points per axis so the body grid has about `nodes` nodes with near-cubic cells."""
    lo, hi = 1e-3, float(max(size))
    for _ in range(60):
        h = 0.5 * (lo + hi)
        n = np.maximum(np.round(size / h).astype(int), 1) + 1
        if np.prod(n) > nodes:
            lo = h
        else:
            hi = h
    return np.maximum(np.round(size / hi).astype(int), 1) + 1


def bag_mesh(size, handles, resolution: int = 400, handle_length: float = 0.12,
             handle_height: float = 0.04) -> TetMesh:
    """Tet mesh of a box `size` (x, y, z) with a handle block on each face direction in `handles`."""
    size = np.asarray(size, dtype=float)
    handles = [np.asarray(h, dtype=float) for h in handles]
    n = _spacing(size, max(int(resolution), 27))
    coords = []
    for ax in range(3):
        c = list(np.linspace(-size[ax] / 2, size[ax] / 2, n[ax]))
        for h in handles:
            if h[ax] < 0:
                c.insert(0, c[0] - handle_height)
            elif h[ax] > 0:
                c.append(c[-1] + handle_height)
        coords.append(np.array(sorted(set(c))))
    shape = np.array([len(c) for c in coords])
    cell_shape = shape - 1
    centres = [0.5 * (c[1:] + c[:-1]) for c in coords]
    cx, cy, cz = np.meshgrid(*centres, indexing="ij")
    cc = np.stack([cx, cy, cz], axis=-1)
    inside = np.all(np.abs(cc) < size / 2, axis=-1)
    keep = inside.copy()
    handle_cells = []
    for h in handles:
        ax = int(np.argmax(np.abs(h)))
        tang = [a for a in range(3) if a != ax]
        out = (cc[..., ax] * np.sign(h[ax])) > size[ax] / 2
        # strap along the longer tangent axis; one cell wide across the other
        long_ax, short_ax = sorted(tang, key=lambda a: -size[a])
        d_long = np.abs(cc[..., long_ax])
        d_short = np.abs(cc[..., short_ax])
        min_short = d_short[out].min()
        within = out & (d_short <= min_short + 1e-9) & (d_long <= max(handle_length / 2, d_long[out].min() + 1e-9))
        keep |= within
        handle_cells.append(within)
    # nodes of the grid
    gx, gy, gz = np.meshgrid(*coords, indexing="ij")
    grid = np.stack([gx, gy, gz], axis=-1).reshape(-1, 3)
    idx = np.arange(np.prod(shape)).reshape(shape)
    tets = []
    for (i, j, k) in np.argwhere(keep):
        corners = [idx[i + a, j + b, k + c] for c in (0, 1) for b in (0, 1) for a in (0, 1)]
        for t in KUHN:
            tets.append([corners[v] for v in t])
    tets = np.array(tets)
    used = np.unique(tets)
    remap = -np.ones(len(grid), dtype=int)
    remap[used] = np.arange(len(used))
    nodes, tets = grid[used], remap[tets]
    a, b, c, d = (nodes[tets[:, i]] for i in range(4))
    det = np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)
    flip = det < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    mesh_handles = []
    for h in handles:
        ax = int(np.argmax(np.abs(h)))
        outer = size[ax] / 2 + handle_height
        sel = np.where(np.abs(nodes[:, ax] * np.sign(h[ax]) - outer) < 1e-9)[0]
        mesh_handles.append(sel)
    mesh = TetMesh(nodes, tets, mesh_handles)
    assert np.all(mesh.volumes() > 0), "tet mesh has non-positive tets"
    return mesh
