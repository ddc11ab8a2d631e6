"""Procedural ISS interior: wall slabs around the union of the keep-in boxes (grown by a margin).

The free space is the union of the grown boxes. Each box gets a slab of wall outside each of its
six faces (extended over the edges); every other grown box is subtracted from every slab, which
cuts the hatches open where boxes overlap. Pure numpy here; `build_pybullet` adds the slabs to a
pybullet client as a few static multibodies (one collider per slab, all convex boxes).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from astrobee import config

MIN_PIECE = 1e-4  # m, slabs thinner than this are dropped


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

    def _candidates(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Slabs that can be nearest to some point of the box [lo, hi]: those whose distance to
        the box is at most the largest distance from the box to the slab nearest its centre."""
        gap = np.maximum(np.maximum(self.walls[:, :3] - hi, lo - self.walls[:, 3:]), 0.0)
        lb = np.linalg.norm(gap, axis=1)
        c = 0.5 * (lo + hi)
        d_c = self._box_sdf(c[None], self.walls)[0]
        k = int(d_c.argmin())
        ub = max(d_c[k], 0.0) + float(np.linalg.norm(hi - lo)) / 2
        return self.walls[lb <= ub + 1e-12]

    def _region(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Candidate slabs for points inside [lo, hi], cached per region (the box grown by
        0.5 m, reused while queries stay inside it; a few regions kept for robots and bag)."""
        return self._region_entry(lo, hi)[2]

    def _region_entry(self, lo: np.ndarray, hi: np.ndarray) -> tuple:
        """(lo, hi, slabs, slab lows, slab highs, slab columns, slabs as lists) of the cached
        region holding [lo, hi]."""
        caches = self.__dict__.setdefault("_caches", [])
        l0, l1, l2 = lo.tolist()
        h0, h1, h2 = hi.tolist()
        for cache in caches:
            (a0, a1, a2), (b0, b1, b2) = cache[0]
            if a0 <= l0 and a1 <= l1 and a2 <= l2 and h0 <= b0 and h1 <= b1 and h2 <= b2:
                return cache[1]
        blo, bhi = lo - 0.5, hi + 0.5
        cand = self._candidates(blo, bhi)
        entry = (blo, bhi, cand, np.ascontiguousarray(cand[:, :3]), np.ascontiguousarray(cand[:, 3:]),
                 [np.ascontiguousarray(cand[:, k]) for k in range(6)], cand.tolist())
        caches.insert(0, ((blo.tolist(), bhi.tolist()), entry))
        del caches[4:]
        return entry

    def wall_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (m) from each point to the nearest wall slab (negative inside a wall).

        Exact: only slabs that can be some point's nearest are evaluated (region cache, then
        a bound from the points' own box).
        """
        p = np.atleast_2d(np.asarray(points, dtype=float))
        lo, hi = p.min(axis=0), p.max(axis=0)
        cand = self._region(lo, hi)
        if len(cand) > 4 and len(p) > 1:
            gap = np.maximum(np.maximum(cand[:, :3] - hi, lo - cand[:, 3:]), 0.0)
            lb = np.linalg.norm(gap, axis=1)
            first = self._box_sdf(p, cand[[int(lb.argmin())]])[:, 0]
            cand = cand[lb <= max(first.max(), 0.0) + 1e-12]
        return self._box_sdf(p, cand).min(axis=1)

    @staticmethod
    def _sdf_cols(p: np.ndarray, cols: list[np.ndarray]) -> np.ndarray:
        """_box_sdf with the boxes given as six (B,) columns, axis by axis: elementwise
        operations only (numpy's reductions over a length-3 last axis cost ~40 ns per output,
        the whole point of this variant); same arithmetic, so the same values."""
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

    def nearest(self, points: np.ndarray) -> tuple[float, int]:
        """Smallest signed wall distance over a point set and the index of the point (exact).

        Small sets are evaluated against every candidate slab of the cached region at once;
        large ones (FEM nodes) first prune the slabs by a lower bound (distance from the points'
        bounding box) against an upper bound (the points' distance to the slab with the
        smallest lower bound).
        """
        p = np.atleast_2d(np.asarray(points, dtype=float))
        lo, hi = p.min(axis=0), p.max(axis=0)
        _, _, walls, w_lo, w_hi, cols, wl = self._region_entry(lo, hi)
        if len(p) <= 8:
            return self._nearest_few(p, lo, hi, w_lo, w_hi, wl, cols)
        if len(p) * len(walls) > 4096:
            gap = np.maximum(np.maximum(w_lo - hi, lo - w_hi), 0.0)
            lb = np.einsum("ij,ij->i", gap, gap)                      # squared lower bounds
            k = int(lb.argmin())
            ub = float(self._box_sdf(p, walls[k:k + 1]).min())
            if ub > 0:
                keep = lb <= ub * ub * (1 + 1e-9) + 1e-18
            else:
                keep = lb <= 0.0
            cols = [c[keep] for c in cols]
        d = self._sdf_cols(p, cols).min(axis=1)
        i = int(d.argmin())
        return float(d[i]), i

    @staticmethod
    def _sdf_one(q: list, w: list) -> float:
        """Signed distance of one point to one box, in floats (same arithmetic as _sdf_cols)."""
        m0 = max(w[0] - q[0], q[0] - w[3])
        m1 = max(w[1] - q[1], q[1] - w[4])
        m2 = max(w[2] - q[2], q[2] - w[5])
        o0, o1, o2 = max(m0, 0.0), max(m1, 0.0), max(m2, 0.0)
        out = math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
        return out if out > 0 else min(max(m0, m1, m2), 0.0)

    def _nearest_few(self, p: np.ndarray, lo, hi, w_lo, w_hi, wl: list, cols: list) -> tuple[float, int]:
        """nearest() for a handful of points (a robot, a box's corners): slabs pruned by the
        bounding-box lower bound in numpy, the survivors evaluated in plain floats when there are
        few point-slab pairs (else in numpy)."""
        pts = p.tolist()
        gap = np.maximum(np.maximum(w_lo - hi, lo - w_hi), 0.0)
        lb = np.einsum("ij,ij->i", gap, gap)                          # squared lower bounds
        sdf = self._sdf_one
        w0 = wl[int(lb.argmin())]
        ub = min(sdf(q, w0) for q in pts)
        keep = np.flatnonzero(lb <= (ub * ub * (1 + 1e-9) + 1e-18 if ub > 0 else 0.0))
        if len(keep) * len(pts) > 12:
            d = self._sdf_cols(p, [c[keep] for c in cols]).min(axis=1)
            i = int(d.argmin())
            return float(d[i]), i
        best, arg = math.inf, 0
        ks = keep.tolist()
        for i, q in enumerate(pts):
            d = min(sdf(q, wl[k]) for k in ks)
            if d < best:
                best, arg = d, i
        return float(best), arg

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


def build_pybullet(world: World, client: int, visuals: bool = False,
                   per_body: int = 64) -> list[int]:
    """Add the wall slabs to a pybullet client as static bodies; returns their ids.

    per_body > 1: compound bodies of up to `per_body` boxes (cheap: 322 separate static bodies
    cost ~22 us a physics step here, 6 compounds ~3 us; multibodies with fixed links far more),
    for rigid-only worlds: pybullet's soft bodies do not collide properly with compounds
    (measured: FEM nodes sank through). per_body <= 1 (FEM worlds) or visuals: one plain box
    body per slab.
    """
    import pybullet as p
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
