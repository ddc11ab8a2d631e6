"""Reduced bag: a grid of rigid blocks tied to their neighbours by point-to-point constraints."""
from __future__ import annotations

import itertools

import numpy as np

from astrobee import rotations as rot

from .rigid_base import RigidPartsBag, box_body


class CompositeBag(RigidPartsBag):
    model = "composite"

    def __init__(self, client: int, variant: str = "front", size=None, mass=None, **params):
        super().__init__(client, variant, size, mass, **params)
        grid = np.asarray(self.params.get("grid", [3, 3, 3]), dtype=int)
        cell = self.size / grid
        self.grid = grid
        idx = list(itertools.product(*(range(g) for g in grid)))
        self.offsets = np.array([(np.array(i) + 0.5) * cell - self.size / 2 for i in idx])
        half = cell / 2 * 0.96           # a small gap so touching blocks do not rub
        self.half_extents = [half] * len(idx)
        m = self.mass / len(idx)
        self.parts = [box_body(self.p, client, half, m, off, [0, 0, 0, 1], (0.8, 0.55, 0.3, 1))
                      for off in self.offsets]
        for a, b in itertools.combinations(range(len(idx)), 2):
            for pa in self.parts[a:a + 1]:
                for pb in self.parts[b:b + 1]:
                    self.p.setCollisionFilterPair(pa, pb, -1, -1, 0, physicsClientId=client)
        self._pairs = [(a, b) for a, b in itertools.combinations(range(len(idx)), 2)
                       if np.sum(np.abs(np.subtract(idx[a], idx[b]))) == 1]
        self.cell = cell
        self.links: list[int] = []
        self._tie()

    def _tie(self) -> None:
        """Ties between face neighbours: one fixed constraint each (`tie: fixed`: measured no
        cheaper), or `tie_points` (3 by default, up to 4) point constraints at the shared face's
        quarter points (`tie: points`, default)."""
        p, c = self.p, self.client
        fmax = float(self.params.get("max_force", 20.0))
        if self.params.get("tie", "points") == "fixed":
            for a, b in self._pairs:
                d = self.offsets[b] - self.offsets[a]
                cid = p.createConstraint(self.parts[a], -1, self.parts[b], -1, p.JOINT_FIXED,
                                         [0, 0, 0], (0.5 * d).tolist(), (-0.5 * d).tolist(),
                                         physicsClientId=c)
                p.changeConstraint(cid, maxForce=fmax, physicsClientId=c)
                self.links.append(cid)
            return
        for a, b in self._pairs:
            d = self.offsets[b] - self.offsets[a]
            ax = int(np.argmax(np.abs(d)))
            t1, t2 = [np.eye(3)[k] * self.cell[k] / 4 for k in range(3) if k != ax]
            mid = 0.5 * d
            corners = ((1, 1), (1, -1), (-1, 1), (-1, -1))
            for s1, s2 in corners[:int(self.params.get("tie_points", 4))]:
                pt = mid + s1 * t1 + s2 * t2
                cid = p.createConstraint(self.parts[a], -1, self.parts[b], -1, p.JOINT_POINT2POINT,
                                         [0, 0, 0], pt.tolist(), (pt - d).tolist(), physicsClientId=c)
                p.changeConstraint(cid, maxForce=fmax, physicsClientId=c)
                self.links.append(cid)

    def grasp(self, k: int, robot) -> None:
        """The grasp model's joint on the handle's block with the five handle constraints'
        budget; clamp: the five spread soft constraints of the seed's model."""
        part = self.part_for_handle(k)
        fmax = float(self.params.get("handle_max_force", 2.5))
        self.hold_handle(k, robot, part, 5 * fmax, clamp=lambda: self._spread(k, robot, part, fmax))
        self.ignore_collisions_with(robot.id)

    def _spread(self, k: int, robot, part: int, fmax: float) -> None:
        st = self.state()
        h = self.handles[k]
        ax = int(np.argmax(np.abs(h)))
        t1, t2 = [np.eye(3)[a] for a in range(3) if a != ax]
        spread = 0.4 * self.handle_length
        for off in (np.zeros(3), t1 * spread, -t1 * spread, t2 * spread, -t2 * spread):
            wp = st.position + rot.rotate(st.orientation, self.handle_point(k) + off)
            self.p2p(robot, part, wp, fmax)
