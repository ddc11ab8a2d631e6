"""Deformable bag: the project's tet mesh as a pybullet mass-spring soft body (deformable world).

Needs a client reset with RESET_USE_DEFORMABLE_WORLD. Node positions come from getMeshData;
velocities are finite differences of successive node positions (getBaseVelocity is wrong for
soft bodies). Snapshot = node positions (+ previous positions for the velocity estimate); the
rigid bodies are snapshotted by the caller's saveState.

Speed (measured round two, 412 nodes, 350 Hz, stiffness 50, damping 0.1): stepSimulation is
~86% of the loop at ~2 ms a step (3x real time needs <= 0.95 ms). Neither numSolverIterations
(50 -> 1), nor filtering or removing every wall, nor filtering the robot-bag contact changed it
beyond noise: the cost is the deformable world's implicit mass-spring solve, whose parameters
pybullet 3.2.7 does not expose.
"""
from __future__ import annotations

import os
import tempfile

import numpy as np

from astrobee import rotations as rot

from .base import Bag, BagState, kabsch
from .mesh import bag_mesh


class FemBag(Bag):
    model = "fem"

    def __init__(self, client: int, variant: str = "front", size=None, mass=None,
                 resolution: int | None = None, **params):
        super().__init__(client, variant, size, mass, **params)
        p = self.p
        res = int(resolution or self.params.get("resolution", 400))
        self.mesh = bag_mesh(self.size, self.handles, res, self.handle_length, self.handle_height)
        fd, path = tempfile.mkstemp(suffix=".vtk", prefix="bag_")
        os.close(fd)
        try:
            self.mesh.write_vtk(path)
            self.id = p.loadSoftBody(
                path, basePosition=[0, 0, 0], baseOrientation=[0, 0, 0, 1], scale=1.0,
                mass=self.mass, useMassSpring=1, useBendingSprings=1, useNeoHookean=0,
                springElasticStiffness=float(self.params.get("elastic_stiffness", 50.0)),
                springDampingStiffness=float(self.params.get("damping", 0.1)),
                springBendingStiffness=float(self.params.get("bending_stiffness", 0.1)),
                springDampingAllDirections=1, useSelfCollision=0,
                frictionCoeff=float(self.params.get("friction", 0.5)),
                collisionMargin=float(self.params.get("collision_margin", 0.006)),
                useFaceContact=1, physicsClientId=client)
        finally:
            os.unlink(path)
        if self.id < 0:
            raise RuntimeError("pybullet could not load the bag's soft body")
        self.num_nodes = len(self.mesh.nodes)
        got = self.nodes()
        if len(got) != self.num_nodes:
            raise RuntimeError(f"soft body has {len(got)} nodes, mesh {self.num_nodes}")
        self.anchors: list[int] = []
        self._prev = got.copy()       # nodes at the previous read (time _t_prev)
        self._cur = got.copy()        # nodes at the last read (time _t_cur)
        self._t = 0.0                 # bag clock, advanced by after_step
        self._t_cur = self._t_prev = 0.0
        self._state: BagState | None = None

    @property
    def body_ids(self) -> list[int]:
        return [self.id]

    def nodes(self) -> np.ndarray:
        n, v = self.p.getMeshData(self.id, -1, flags=self.p.MESH_DATA_SIMULATION_MESH,
                                  physicsClientId=self.client)
        return np.asarray(v, dtype=float).reshape(-1, 3)

    def set_nodes(self, x: np.ndarray) -> None:
        self.p.resetMeshData(self.id, vertices=np.asarray(x, dtype=float).tolist(),
                             physicsClientId=self.client)

    def set_pose(self, position, orientation) -> None:
        x = np.asarray(position) + rot.rotate(np.asarray(orientation), self.mesh.nodes)
        self.set_nodes(x)
        self._prev, self._cur = x.copy(), x.copy()
        self._t_prev = self._t_cur = self._t
        self._state = None

    def grasp(self, k: int, robot) -> None:
        link = robot.links["gripper"]
        # the anchored handle sits inside the gripper: no soft contact with the arm
        for ln in ("gripper", "arm_distal", "arm_proximal"):
            self.p.setCollisionFilterPair(self.id, robot.id, -1, robot.links[ln], 0,
                                          physicsClientId=self.client)
        # the grasp model picks the pinned nodes (astrobee_sim.grasp): Bullet's anchors are rigid
        # pins, so a strap is one pinned node (a ball joint, no twist spring), a hinge two
        for node in self.grasp_model.bullet_nodes(self.mesh.nodes,
                                                  np.asarray(self.mesh.handle_nodes[k]),
                                                  self.handle_point(k), self.strap_axis(k)):
            self.anchors.append(self.p.createSoftBodyAnchor(self.id, int(node), robot.id, link,
                                                            physicsClientId=self.client))

    def release(self) -> None:
        for a in self.anchors:
            self.p.removeConstraint(a, physicsClientId=self.client)
        self.anchors = []
        self.attached = [False] * len(self.handles)

    def after_step(self, dt: float, sample: bool = True) -> None:
        """Advance the bag clock; read the nodes when `sample` (the simulation asks on the last
        two steps of each step() call: velocities then span one physics step whatever the
        caller reads, and reading every step would cost ~20% of a step)."""
        self._t += dt
        if sample:
            self._refresh()

    def _refresh(self) -> None:
        if self._t > self._t_cur:
            self._prev, self._t_prev = self._cur, self._t_cur
            self._cur, self._t_cur = self.nodes(), self._t
            self._state = None

    def points(self) -> np.ndarray:
        self._refresh()
        return self._cur

    def state(self) -> BagState:
        self._refresh()
        if self._state is not None:
            return self._state
        q, c = kabsch(self.mesh.nodes, self._cur)
        q0, c0 = kabsch(self.mesh.nodes, self._prev)
        dt = self._t_cur - self._t_prev
        if dt > 0:
            v = (c - c0) / dt
            w = rot.rotate(q0, rot.to_rotvec(rot.multiply(rot.conjugate(q0), q))) / dt
        else:
            v, w = np.zeros(3), np.zeros(3)
        rest = c + rot.rotate(q, self.mesh.nodes - self.mesh.nodes.mean(axis=0))
        deform = float(np.sqrt(np.mean(np.sum((self._cur - rest) ** 2, axis=1))))
        # the bag frame origin is the box centre: the rest centroid sits off it by the handles
        pos = c - rot.rotate(q, self.mesh.nodes.mean(axis=0))
        self._state = BagState(pos, q, v, w, deform, list(self.attached))
        return self._state

    def snapshot(self):
        self._refresh()
        return {"cur": self._cur.copy(), "prev": self._prev.copy(), "t": self._t,
                "t_prev": self._t_prev}

    def restore(self, snap) -> None:
        """Put every node back where it was (exact, via resetMeshData).

        Node velocities cannot be read or set in pybullet 3.2.7: after a restore the nodes keep
        the velocities they had just before it. Measured (tests/sim/test_snapshot.py): positions
        back to 0 m error, but 0.64 s after restoring mid-motion the nodes are ~8 mm off the
        original continuation (the rigid bodies ~1 cm, dragged by the bag). The error is that
        of the velocity mismatch: small when the bag moves with the robot as a whole, zero for
        a snapshot taken and restored at rest.
        """
        self.set_nodes(snap["cur"])
        self._cur, self._prev = snap["cur"].copy(), snap["prev"].copy()
        self._t = self._t_cur = snap["t"]
        self._t_prev = snap["t_prev"]
        self._state = None
