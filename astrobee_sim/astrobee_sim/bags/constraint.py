"""Reduced bag: one rigid box held by a handle of soft point-to-point constraints (max force ~2.5 N)."""
from __future__ import annotations

import numpy as np

from astrobee import rotations as rot

from .rigid_base import RigidPartsBag, box_body


class ConstraintBag(RigidPartsBag):
    model = "constraint"

    def __init__(self, client: int, variant: str = "front", size=None, mass=None, **params):
        super().__init__(client, variant, size, mass, **params)
        self.half_extents = [self.size / 2]
        self.offsets = np.zeros((1, 3))
        self.parts = [box_body(self.p, client, self.size / 2, self.mass, [0, 0, 0], [0, 0, 0, 1])]

    def grasp(self, k: int, robot) -> None:
        """The grasp model's joint at the handle with the whole budget of the soft constraints
        (num_constraints x max_force); clamp: the spread soft constraints of the seed's model."""
        n = int(self.params.get("num_constraints", 5))
        fmax = float(self.params.get("max_force", 2.5))
        self.hold_handle(k, robot, 0, n * fmax, clamp=lambda: self._spread(k, robot, n, fmax))
        robot_ignore(self, robot)

    def _spread(self, k: int, robot, n: int, fmax: float) -> None:
        st = self.state()
        h = self.handles[k]
        ax = int(np.argmax(np.abs(h)))
        t1, t2 = [np.eye(3)[a] for a in range(3) if a != ax]
        spread = 0.4 * self.handle_length
        local = [np.zeros(3), t1 * spread, -t1 * spread, t2 * spread, -t2 * spread][:n]
        for off in local:
            wp = st.position + rot.rotate(st.orientation, self.handle_point(k) + off)
            self.p2p(robot, 0, wp, fmax)


def robot_ignore(bag, robot) -> None:
    bag.ignore_collisions_with(robot.id)
