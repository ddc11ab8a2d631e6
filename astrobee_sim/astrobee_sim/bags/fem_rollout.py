"""K independent copies of robot + fast FEM bag stepped in one call, for rollouts (no pybullet).

The robot is one rigid body (whole-robot mass and inertia from config/astrobee.yaml, the arm held
rigid, the gripper a fixed point of the body) whose collision box (centred on the body frame's
origin, as in robot.py's URDF) collides with the wall slabs (rigid_walls.BoxWalls); the bag is
mass_spring's model held as the bag's grasp model holds it (anchor springs, tethers, the
strap's twist spring), with the same wall-slab and robot-box contacts as
fem_fast.FastFemBag. All copies share one factored matrix: a step is a few array operations
over (N, K, 3) plus one matrix product.
"""
from __future__ import annotations

import numpy as np

from astrobee import config

from ..grasp import twist_forces
from .mass_spring import Anchors, MassSpring, Tethers
from .node_contacts import collide_moving_boxes, collide_static_boxes, grow_boxes
from .rigid_walls import BoxWalls


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products of (K, 4) quaternions [x,y,z,w]."""
    ax, ay, az, aw = a.T
    bx, by, bz, bw = b.T
    return np.stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz], 1)


class FemRollout:
    """K copies of (rigid robot, FEM bag): `step(wrench_body, n)` advances all of them."""

    def __init__(self, springs: MassSpring, anchors: Anchors, grip_offsets: np.ndarray,
                 walls: np.ndarray, box_half: np.ndarray, k: int, dt: float,
                 margin: float = 0.006, friction: float = 0.5, robot_walls: bool = True,
                 robot_friction: float = 0.25, tethers: Tethers | None = None,
                 tether_offsets: np.ndarray | None = None, twist: dict | None = None):
        """robot_walls False: the robot body passes through the walls (the bag still collides);
        robot_friction: robot-wall Coulomb friction (Bullet's 0.5 x 0.5 of pybullet's run).
        tethers / tether_offsets (G, 3 body frame, from COM): node groups held by their
        centroids; twist: the strap's twist spring (w its grasp.twist_weights, u and n body-frame
        unit vectors, k, c; astrobee_sim.grasp.twist_forces)."""
        cfg = config.astrobee()
        self.springs, self.anchors = springs, anchors
        self.offsets = np.asarray(grip_offsets, dtype=float).reshape(-1, 3)   # (A, 3) body, from COM
        self.tethers = tethers
        self.tether_offsets = (np.zeros((0, 3)) if tether_offsets is None
                               else np.asarray(tether_offsets, dtype=float).reshape(-1, 3))
        self.twist = twist
        self._held = np.unique(np.concatenate([np.asarray(anchors.nodes, dtype=int)]
                                              + ([np.asarray(g, dtype=int) for g in tethers.groups]
                                                 if tethers is not None else []))).astype(int)
        self.walls, self.half = np.asarray(walls, dtype=float), np.asarray(box_half, dtype=float)
        self.k, self.dt, self.margin, self.friction = int(k), float(dt), margin, friction
        self.mass = float(cfg["mass"])
        self.inertia = np.asarray(cfg["inertia"], dtype=float)    # diagonal, body frame
        self.box_offset = -np.asarray(cfg["com_offset"], dtype=float)   # box centre from COM
        self._walls_grown = grow_boxes(self.walls, margin)
        self.robot_walls = (BoxWalls(self.walls, self.half, self.box_offset, self.mass,
                                     self.inertia, 0.0, robot_friction) if robot_walls else None)
        self.wall_depth = np.zeros(self.k)     # robot into a wall, deepest over the last step()
        n = springs.n
        self.x = np.zeros((n, self.k, 3))
        self.v = np.zeros((n, self.k, 3))
        self.pos = np.zeros((self.k, 3))                          # robot COM, world
        self.q = np.tile([0.0, 0.0, 0.0, 1.0], (self.k, 1))
        self.vel = np.zeros((self.k, 3))
        self.omega = np.zeros((self.k, 3))                        # world frame
        self.force = np.zeros((self.k, 3))                        # bag on robot, next step
        self.torque = np.zeros((self.k, 3))
        self.time = 0.0

    @classmethod
    def from_bag(cls, bag, robot, k: int, dt: float, **kw) -> "FemRollout":
        """K copies of a FastFemBag and the robot holding its first handle, in their current
        state (the robot's velocity and spin included) and held by the bag's grasp model;
        kw: the constructor's options."""
        from .fem_fast import quat_matrices
        pos, q, vel, w = robot.state()
        com = robot.com()
        R = quat_matrices(q[None])[0]
        g = bag._grasps[0]
        hold = g["hold"]
        na, nt = len(hold.anchors), len(hold.tethers)
        anchors = Anchors(hold.anchors, bag._anchors.stiffness[:na], bag._anchors.damping[:na])
        tethers = (Tethers(list(hold.tethers), bag._tethers.stiffness[:nt],
                           bag._tethers.damping[:nt]) if nt else None)
        t = bag._target[:na, 0]
        tt = bag._tether_target[:nt, 0] if nt else np.zeros((0, 3))
        twist = None
        if hold.twist is not None:
            _, Rg, _, _, _ = bag._gripper(robot)
            twist = {"w": g["tw"], "u": R.T @ (Rg @ g["u"]),
                     "n": R.T @ (Rg @ g["n"]), "k": hold.twist_stiffness,
                     "c": hold.twist_damping}
        ro = cls(bag.springs, anchors, (t - com) @ R, bag.walls, bag.half, k, dt,
                 bag.margin, bag.friction, tethers=tethers, tether_offsets=(tt - com) @ R,
                 twist=twist, **kw)
        ro.x[...] = bag.x
        ro.v[...] = bag.v
        ro.pos[...] = com
        ro.q[...] = q
        ro.vel[...] = vel + np.cross(w, com - pos)
        ro.omega[...] = w
        return ro

    # ---- state -----------------------------------------------------------------------------
    _FIELDS = ("x", "v", "pos", "q", "vel", "omega", "force", "torque")

    def snapshot(self) -> dict:
        return {f: getattr(self, f).copy() for f in self._FIELDS} | {"time": self.time}

    def restore(self, snap: dict) -> None:
        for f in self._FIELDS:
            getattr(self, f)[...] = snap[f]
        self.time = snap["time"]

    def bag_com(self) -> np.ndarray:
        """(K, 3) centre of mass of each copy's bag."""
        return self.x.mean(axis=0)

    # ---- stepping --------------------------------------------------------------------------
    def step(self, wrench_body: np.ndarray, n: int = 1) -> None:
        """Advance every copy n steps holding body-frame wrenches (K, 6) (or one (6,) for all)."""
        from .fem_fast import quat_matrices
        h, m, inertia = self.dt, self.mass, self.inertia
        wb = np.broadcast_to(np.asarray(wrench_body, dtype=float), (self.k, 6))
        self.wall_depth = np.zeros(self.k)
        for _ in range(n):
            R = quat_matrices(self.q)
            pos_prev, R_prev = self.pos.copy(), R
            f = np.einsum("kij,kj->ki", R, wb[:, :3]) + self.force
            tau = np.einsum("kij,kj->ki", R, wb[:, 3:]) + self.torque
            # rigid robot: semi-implicit Euler, Euler's equations in the body frame
            self.vel += (h / m) * f
            wbody = np.einsum("kji,kj->ki", R, self.omega)
            tb = np.einsum("kji,kj->ki", R, tau) - np.cross(wbody, inertia * wbody)
            wbody = wbody + h * tb / inertia
            self.omega = np.einsum("kij,kj->ki", R, wbody)
            self.pos += h * self.vel
            half = 0.5 * h * self.omega
            ang = np.linalg.norm(half, axis=1, keepdims=True)
            s = np.where(ang > 1e-12, np.sin(ang) / np.maximum(ang, 1e-300), 1.0)
            dq = np.concatenate([half * s, np.cos(ang)], axis=1)
            self.q = _quat_mul(dq, self.q)
            self.q /= np.linalg.norm(self.q, axis=1, keepdims=True)
            R = quat_matrices(self.q)
            if self.robot_walls is not None:
                d = self.robot_walls.collide(self.pos, R, self.vel, self.omega, pos_prev, R_prev)
                np.maximum(self.wall_depth, d, out=self.wall_depth)
            # anchor and tether targets on the (rigid) gripper
            arm = np.einsum("kij,aj->aki", R, self.offsets)            # (A, K, 3)
            target = self.pos[None] + arm
            target_vel = self.vel[None] + np.cross(self.omega[None], arm)
            tarm = np.einsum("kij,aj->aki", R, self.tether_offsets)    # (G, K, 3)
            ttarget = self.pos[None] + tarm
            tvel = self.vel[None] + np.cross(self.omega[None], tarm)
            x, v = self.x, self.v
            external, twist_tau = None, 0.0
            if self.twist is not None:
                tw = self.twist
                fa, twist_tau = twist_forces(x, v, tw["w"], R @ tw["n"], R @ tw["u"], self.omega,
                                             tw["k"], tw["c"])
                external = np.zeros_like(x)
                a, b = tw["w"] > 0, tw["w"] < 0
                external[a] += fa / np.count_nonzero(a)
                external[b] -= fa / np.count_nonzero(b)
            x_prev = x.copy()
            self.springs.step(x, v, h, self.anchors, target, target_vel, external,
                              self.tethers, ttarget, tvel)
            collide_static_boxes(x.reshape(-1, 3), v.reshape(-1, 3), x_prev.reshape(-1, 3),
                                 self.walls, self.margin, self.friction, self._walls_grown)
            # the body box is centred on the body frame's origin, not on the COM
            box = np.einsum("kij,j->ki", R, self.box_offset)
            fc, tc = collide_moving_boxes(x, v, x_prev, self.pos + box, R,
                                          self.vel + np.cross(self.omega, box), self.omega,
                                          self.half, self.margin, self.friction,
                                          self.springs.node_mass, h, self._held)
            fa = self.springs.anchor_forces(x, v, self.anchors, target, target_vel)
            self.force = fa.sum(axis=0) + fc
            self.torque = np.cross(arm, fa).sum(axis=0) + tc + np.cross(box, fc) + twist_tau
            if self.tethers is not None:
                ft = self.springs.tether_forces(x, v, self.tethers, ttarget, tvel)
                self.force += ft.sum(axis=0)
                self.torque += np.cross(tarm, ft).sum(axis=0)
            self.time += h
