"""Procedural ISS interior: wall slabs around the union of the keep-in boxes (grown by a margin).

The free space is the union of the grown boxes. Each box gets a slab of wall outside each of its
six faces (extended over the edges); every other grown box is subtracted from every slab, which
cuts the hatches open where boxes overlap. Pure numpy here; `build_pybullet` adds the slabs to a
pybullet client as a few static multibodies (one collider per slab, all convex boxes).

The smallest wall distance of a point set (the sim's clearance, every tick) is one numba loop
over the candidate slabs of the points' grid cells where numba is loaded (sim_node loads it;
~1-3 us for a robot or a rigid bag's corners, ~55 us for 412 FEM nodes, instead of ~10 / ~23 /
~120 us of numpy calls), the same arithmetic as the numpy path, so the same values.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import numpy as np

from astrobee import config

MIN_PIECE = 1e-4  # m, slabs thinner than this are dropped
CELL = 0.25       # m, grid cell of the wall-distance candidate cache (point sets)
FINE = 0.1        # m, the same for single points (robots): fewer candidates per cell


def _min_sdf_loop(p, boxes):  # pragma: no cover - compiled
    """(smallest signed distance, index of its first point) of points p (P, 3) to boxes (B, 6):
    World._sdf_one's arithmetic per pair, the first point reaching the minimum as numpy's argmin."""
    best = np.inf
    bi = 0
    for i in range(p.shape[0]):
        q0, q1, q2 = p[i, 0], p[i, 1], p[i, 2]
        for j in range(boxes.shape[0]):
            m0 = max(boxes[j, 0] - q0, q0 - boxes[j, 3])
            m1 = max(boxes[j, 1] - q1, q1 - boxes[j, 4])
            m2 = max(boxes[j, 2] - q2, q2 - boxes[j, 5])
            o0, o1, o2 = max(m0, 0.0), max(m1, 0.0), max(m2, 0.0)
            out = math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
            d = out if out > 0 else min(max(max(m0, m1), m2), 0.0)
            if d < best:
                best = d
                bi = i
    return best, bi


_min_sdf = None      # the compiled loop once loaded; False: numba missing (numpy path)


def min_sdf_kernel(load: bool = False):
    """The compiled _min_sdf_loop, or None (the numpy path, same values).

    Loaded when numba is already imported in this process (the fast FEM solvers import it) or
    when `load` (sim_node asks at start): importing numba and loading the cached loop cost
    ~0.4 s wall (~0.6 s CPU) once per process, which the ~30 us a tick saved repays only after
    ~10-15k ticks, so a process that does not use numba otherwise does not pay it by default."""
    global _min_sdf
    if _min_sdf is None and (load or "numba" in sys.modules):
        try:
            from numba import njit
        except ImportError:
            _min_sdf = False
        else:
            _min_sdf = njit(cache=True)(_min_sdf_loop)
            _min_sdf(np.zeros((1, 3)), np.ones((1, 6)))
    return _min_sdf or None


def subtract_box(a: np.ndarray, b: np.ndarray) -> list[np.ndarray]:
    """Pieces of box a (xmin..zmax) not inside box b: up to 6 disjoint boxes."""
    lo_a, hi_a = a[:3].copy(), a[3:].copy()
    lo_b, hi_b = b[:3], b[3:]
    if np.any(hi_a <= lo_b) or np.any(hi_b <= lo_a):
        return [a]
    out = []
    for ax in range(3):
        if lo_a[ax] < lo_b[ax]:
            lo, hi = lo_a.copy(), hi_a.copy()
            hi[ax] = lo_b[ax]
            out.append(np.concatenate([lo, hi]))
            lo_a[ax] = lo_b[ax]
        if hi_a[ax] > hi_b[ax]:
            lo, hi = lo_a.copy(), hi_a.copy()
            lo[ax] = hi_b[ax]
            out.append(np.concatenate([lo, hi]))
            hi_a[ax] = hi_b[ax]
    return out


def subtract_all(a: np.ndarray, others: np.ndarray) -> list[np.ndarray]:
    pieces = [a]
    for b in others:
        nxt = []
        for p in pieces:
            nxt.extend(subtract_box(p, b))
        pieces = nxt
    return [p for p in pieces if np.all(p[3:] - p[:3] > MIN_PIECE)]


def wall_slabs(free_boxes: np.ndarray, thickness: float) -> np.ndarray:
    """(M, 6) wall boxes enclosing the union of `free_boxes` (each an xmin..zmax row)."""
    slabs = []
    for i, box in enumerate(free_boxes):
        others = np.delete(free_boxes, i, axis=0)
        lo, hi = box[:3], box[3:]
        for ax in range(3):
            for side in (0, 1):
                s_lo = lo - thickness
                s_hi = hi + thickness
                if side == 0:
                    s_hi = s_hi.copy(); s_hi[ax] = lo[ax]
                else:
                    s_lo = s_lo.copy(); s_lo[ax] = hi[ax]
                slabs.extend(subtract_all(np.concatenate([s_lo, s_hi]), others))
    return np.array(slabs)


@dataclass
class World:
    """The station geometry: free-space boxes, wall slabs and module labels (no pybullet)."""
    keep_in: np.ndarray          # (N, 6) the robot's keep-in boxes
    free: np.ndarray             # (N, 6) keep-in grown by the wall margin
    walls: np.ndarray            # (M, 6) wall slabs
    modules: list[str]           # module name of each keep-in box
    margin: float
    thickness: float

    @classmethod
    def from_config(cls, margin: float | None = None, thickness: float | None = None) -> "World":
        cfg = config.iss()
        margin = float(cfg.get("wall_margin", 0.1) if margin is None else margin)
        thickness = float(cfg.get("sim_wall_thickness", cfg.get("wall_thickness", 0.05))
                          if thickness is None else thickness)
        keep = config.keep_in_boxes()
        free = keep + np.array([-margin] * 3 + [margin] * 3)
        mods = [k.get("module", "") for k in cfg["keep_in"]]
        return cls(keep, free, wall_slabs(free, thickness), mods, margin, thickness)

    def in_free_space(self, points: np.ndarray) -> np.ndarray:
        """Boolean per point: inside the union of the grown keep-in boxes."""
        p = np.atleast_2d(np.asarray(points, dtype=float))
        inside = np.all((p[:, None, :] >= self.free[None, :, :3]) &
                        (p[:, None, :] <= self.free[None, :, 3:]), axis=2)
        return inside.any(axis=1)

    @staticmethod
    def _box_sdf(p: np.ndarray, boxes: np.ndarray) -> np.ndarray:
        """(P, B) signed distance from points to boxes (negative inside).

        Per axis m = max(lo - q, q - hi) (> 0 outside on that axis): outside distance
        |max(m, 0)|, inside depth max over axes of m (= -min(q - lo, hi - q), exactly).
        """
        q = p[:, None, :]
        m = np.maximum(boxes[None, :, :3] - q, q - boxes[None, :, 3:])
        o = np.maximum(m, 0.0)
        outside = np.sqrt(np.add.reduce(o * o, axis=2))
        return np.where(outside > 0, outside, np.minimum(m.max(axis=2), 0.0))

    # ---- exact wall-distance queries through a lazily filled grid of candidate slabs --------
    # Each CELL-sized grid cell keeps the few slabs that can be nearest to some point in it: a
    # slab stays when its distance to the cell is at most the smallest, over all slabs, of the
    # cell's farthest distance to that slab (the nearest slab of any point in the cell passes
    # this test, so the answer is exact). A query takes the union over the cells of the points'
    # bounding box (cached per box of cells) and evaluates only those slabs: ~5-15 instead of
    # the station's ~400, a few microseconds per query instead of a scan.

    def _cell_slabs(self, key: tuple, size: float = CELL) -> np.ndarray:
        """Indices of the slabs that can be nearest to a point of grid cell `key` (cells of
        `size` metres)."""
        cells = self.__dict__.setdefault("_cells", {}).setdefault(size, {})
        idx = cells.get(key)
        if idx is None:
            lo = np.asarray(key, dtype=float) * size
            hi = lo + size
            w_lo, w_hi = self.walls[:, :3], self.walls[:, 3:]
            gap = np.maximum(np.maximum(w_lo - hi, lo - w_hi), 0.0)
            lb = np.einsum("ij,ij->i", gap, gap)
            # farthest point of the cell from each slab: per axis (the squared distance is a sum
            # of convex per-axis terms) the worse of the cell's two faces
            far = np.maximum(np.maximum(np.maximum(w_lo - lo, lo - w_hi),
                                        np.maximum(w_lo - hi, hi - w_hi)), 0.0)
            ub = float(np.einsum("ij,ij->i", far, far).min())
            idx = np.flatnonzero(lb <= ub * (1 + 1e-9) + 1e-18)
            cells[key] = idx
        return idx

    def _block(self, klo: list, khi: list, size: float = CELL) -> tuple:
        """(slab columns, slabs as lists, slab lows, slab highs, slabs (B, 6)) of the union of
        the cells klo..khi (inclusive)."""
        key = (*klo, *khi, size)
        blocks = self.__dict__.setdefault("_blocks", {})
        entry = blocks.get(key)
        if entry is None:
            ids = [self._cell_slabs((i, j, k), size)
                   for i in range(klo[0], khi[0] + 1)
                   for j in range(klo[1], khi[1] + 1)
                   for k in range(klo[2], khi[2] + 1)]
            sel = self.walls[np.unique(np.concatenate(ids))]
            sel = np.ascontiguousarray(sel)
            entry = ([np.ascontiguousarray(sel[:, k]) for k in range(6)], sel.tolist(),
                     np.ascontiguousarray(sel[:, :3]), np.ascontiguousarray(sel[:, 3:]), sel)
            if len(blocks) >= 512:             # the robots move on: forget the oldest boxes
                del blocks[next(iter(blocks))]
            blocks[key] = entry
        return entry

    def wall_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (m) from each point to the nearest wall slab (negative inside a wall).

        Exact (only slabs that cannot be any point's nearest are skipped)."""
        p = np.atleast_2d(np.asarray(points, dtype=float))
        keys = np.floor(p * (1.0 / CELL)).astype(int)
        klo, khi = keys.min(axis=0), keys.max(axis=0)
        if np.prod(khi - klo + 1) <= 64:      # one box of cells (a bag, a robot)
            cols = self._block(klo.tolist(), khi.tolist())[0]
            return self._sdf_cols(p, cols).min(axis=1)
        out = np.empty(len(p))               # points spread over the station: cell by cell
        uniq, inv = np.unique(keys, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        order = np.argsort(inv, kind="stable")
        bounds = np.searchsorted(inv[order], np.arange(len(uniq) + 1))
        for u, k in enumerate(uniq.tolist()):
            sel = order[bounds[u]:bounds[u + 1]]
            cols = self._block(k, k)[0]
            out[sel] = self._sdf_cols(p[sel], cols).min(axis=1)
        return out

    @staticmethod
    def _sdf_cols(p: np.ndarray, cols: list[np.ndarray]) -> np.ndarray:
        """(P, B) signed distances with the boxes given as six (B,) columns, axis by axis:
        elementwise operations only (numpy's reductions over a length-3 last axis cost ~40 ns
        per output); the same arithmetic as _box_sdf, so the same values."""
        out2 = mx = None
        for ax in range(3):
            q = p[:, ax:ax + 1]
            m = np.maximum(cols[ax] - q, q - cols[ax + 3])
            o = np.maximum(m, 0.0)
            if out2 is None:
                out2, mx = o * o, m
            else:
                out2 = out2 + o * o
                mx = np.maximum(mx, m)
        outside = np.sqrt(out2)
        return np.where(outside > 0, outside, np.minimum(mx, 0.0))

    @staticmethod
    def _sdf_one(q: list, w: list) -> float:
        """Signed distance of one point to one box, in floats (same arithmetic as _sdf_cols)."""
        m0 = max(w[0] - q[0], q[0] - w[3])
        m1 = max(w[1] - q[1], q[1] - w[4])
        m2 = max(w[2] - q[2], q[2] - w[5])
        o0, o1, o2 = max(m0, 0.0), max(m1, 0.0), max(m2, 0.0)
        out = math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
        return out if out > 0 else min(max(m0, m1, m2), 0.0)

    def nearest(self, points: np.ndarray) -> tuple[float, int]:
        """Smallest signed wall distance over a point set and the index of that point (exact)."""
        p = np.ascontiguousarray(np.atleast_2d(np.asarray(points, dtype=float)))
        kern = min_sdf_kernel()
        if len(p) == 1:                      # a robot: plain floats beat numpy's per-call cost
            q = p[0].tolist()
            k = [math.floor(c * (1.0 / FINE)) for c in q]
            cols, wl, _, _, sel = self._block(k, k, FINE)
            if kern is not None:
                return float(kern(p, sel)[0]), 0
            if len(wl) > 12:
                return float(self._sdf_cols(p, cols).min()), 0
            sdf = self._sdf_one
            return float(min(sdf(q, w) for w in wl)), 0
        # the cells of the points' bounding box (floor is monotonic: the keys' min and max)
        klo = [math.floor(c * (1.0 / CELL)) for c in p.min(axis=0).tolist()]
        khi = [math.floor(c * (1.0 / CELL)) for c in p.max(axis=0).tolist()]
        if (khi[0] - klo[0] + 1) * (khi[1] - klo[1] + 1) * (khi[2] - klo[2] + 1) > 64:
            d = self.wall_distance(p)
        else:
            cols, _, w_lo, w_hi, sel = self._block(klo, khi)
            if len(p) * len(w_lo) > 1024:    # FEM nodes: keep the slabs that can hold the minimum
                lo, hi = p.min(axis=0), p.max(axis=0)
                gap = np.maximum(np.maximum(w_lo - hi, lo - w_hi), 0.0)
                lb = np.einsum("ij,ij->i", gap, gap)          # squared, to the points' box
                k = int(lb.argmin())
                ub = (float(kern(p, sel[k:k + 1])[0]) if kern is not None
                      else float(self._sdf_cols(p, [c[k:k + 1] for c in cols]).min()))
                keep = lb <= (ub * ub * (1 + 1e-9) + 1e-18 if ub > 0 else 0.0)
                cols, sel = [c[keep] for c in cols], sel[keep]
            if kern is not None:
                best, i = kern(p, sel)
                return float(best), int(i)
            d = self._sdf_cols(p, cols).min(axis=1)
        i = int(d.argmin())
        return float(d[i]), i

    def clearance(self, points: np.ndarray) -> float:
        """Smallest signed wall distance over a set of points (e.g. a bag's nodes)."""
        return self.nearest(points)[0]


MODULE_COLOURS = {
    "node_1": (0.85, 0.85, 0.80), "us_lab": (0.75, 0.80, 0.90), "node_2": (0.85, 0.85, 0.80),
    "eu_lab": (0.80, 0.90, 0.75), "jem": (0.90, 0.85, 0.70), "node_3": (0.85, 0.80, 0.85),
    "cupola": (0.70, 0.85, 0.90),
}


def module_colour(name: str) -> tuple[float, float, float]:
    return MODULE_COLOURS.get(name.split("/")[0], (0.8, 0.8, 0.8))


_STATIONS: dict[float, World] = {}


def sim_defaults() -> dict:
    """The `simulator:` section of config/astrobee.yaml (empty if absent)."""
    return dict(config.astrobee().get("simulator") or {})


def station(wall_thickness: float = 0.25) -> World:
    """The procedural ISS geometry (cached per thickness: it only depends on config/iss.yaml).

    The sim's walls are thicker than iss.yaml's 5 cm so a soft-body node pushed hard into a wall
    (penetration up to a few cm measured) can never come out on the far side.
    """
    if wall_thickness not in _STATIONS:
        _STATIONS[wall_thickness] = World.from_config(thickness=wall_thickness)
    return _STATIONS[wall_thickness]


# pybullet 3.2.7's createCollisionShapeArray keeps the first 16 children of a compound and
# silently drops the rest (MAX_COMPOUND_COLLISION_SHAPES in its C API): with 64 boxes a body,
# 233 of the station's 426 slabs were missing and a robot flew out through Node 2's ceiling.
MAX_COMPOUND_CHILDREN = 16


def build_pybullet(world: World, client: int, visuals: bool = False,
                   per_body: int = 64) -> list[int]:
    """Add the wall slabs to a pybullet client as static bodies; returns their ids.

    per_body > 1: compound bodies of up to `per_body` boxes, at most MAX_COMPOUND_CHILDREN
    (cheap: 426 separate static bodies cost ~22 us a physics step here, 27 compounds ~4 us;
    multibodies with fixed links far more), for rigid-only worlds: pybullet's soft bodies do
    not collide properly with compounds (measured: FEM nodes sank through). per_body <= 1 (FEM
    worlds) or visuals: one plain box body per slab.
    """
    from .pybullet_import import pybullet
    p = pybullet()
    per_body = min(per_body, MAX_COMPOUND_CHILDREN)
    ids = []
    owner = _slab_module(world)
    w = world.walls
    half = ((w[:, 3:] - w[:, :3]) / 2).tolist()
    pos = ((w[:, 3:] + w[:, :3]) / 2).tolist()
    if per_body <= 1 or visuals:
        # one plain (non-compound) static box per slab; also the GUI path: per-slab colours
        # need separate visual shapes (pybullet 3.2.7 crashed on compound visual arrays here)
        for k in range(len(w)):
            col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half[k], physicsClientId=client)
            vis = -1
            if visuals:
                vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half[k], physicsClientId=client,
                                          rgbaColor=[*module_colour(owner[k]), 0.35])
            ids.append(p.createMultiBody(baseMass=0, baseCollisionShapeIndex=col,
                                         baseVisualShapeIndex=vis, basePosition=pos[k],
                                         useMaximalCoordinates=True, physicsClientId=client))
        return ids
    for k in range(0, len(w), per_body):
        sl = slice(k, k + per_body)
        n = len(half[sl])
        col = p.createCollisionShapeArray([p.GEOM_BOX] * n, halfExtents=half[sl],
                                          collisionFramePositions=pos[sl], physicsClientId=client)
        ids.append(p.createMultiBody(baseMass=0, baseCollisionShapeIndex=col,
                                     useMaximalCoordinates=True, physicsClientId=client))
    return ids


def _slab_module(world: World) -> list[str]:
    """Module of the free box each slab is nearest to (for colours)."""
    c = (world.walls[:, :3] + world.walls[:, 3:]) / 2
    fc = (world.free[:, :3] + world.free[:, 3:]) / 2
    d = np.linalg.norm(c[:, None, :] - fc[None, :, :], axis=2)
    return [world.modules[i] for i in d.argmin(axis=1)]
