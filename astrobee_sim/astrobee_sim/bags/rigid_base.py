"""Shared machinery of the reduced (rigid-body) bag models: boxes, grasp constraints, state."""
from __future__ import annotations

import numpy as np

from astrobee import rotations as rot

from ..robot import qrot
from .base import Bag, BagState, kabsch


def box_body(p, client: int, half, mass: float, position, orientation, rgba=(0.8, 0.6, 0.3, 1),
             maximal: bool = True) -> int:
    """A dynamic box; maximal coordinates (a plain btRigidBody) unless asked otherwise."""
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(half), physicsClientId=client)
    vis = p.createVisualShape(p.GEOM_BOX, halfExtents=list(half), rgbaColor=list(rgba),
                              physicsClientId=client)
    b = p.createMultiBody(baseMass=mass, baseCollisionShapeIndex=col, baseVisualShapeIndex=vis,
                          basePosition=list(position), baseOrientation=list(orientation),
                          useMaximalCoordinates=maximal, physicsClientId=client)
    p.changeDynamics(b, -1, linearDamping=0, angularDamping=0,
                     activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING, physicsClientId=client)
    return b


def to_frame(pos, orn, world_point) -> list[float]:
    """World point expressed in the frame (pos, orn)."""
    return rot.rotate_inverse(np.asarray(orn), np.asarray(world_point) - np.asarray(pos)).tolist()


def quat_matrices(Q: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices of (n, 4) quaternions [x,y,z,w] (Bullet's formula, vectorised:
    one call instead of a getMatrixFromQuaternion per part)."""
    x, y, z, w = Q[:, 0], Q[:, 1], Q[:, 2], Q[:, 3]
    s = 2.0 / (x * x + y * y + z * z + w * w)
    xs, ys, zs = x * s, y * s, z * s
    wx, wy, wz = w * xs, w * ys, w * zs
    xx, xy, xz = x * xs, x * ys, x * zs
    yy, yz, zz = y * ys, y * zs, z * zs
    return np.stack([1.0 - (yy + zz), xy - wz, xz + wy,
                     xy + wz, 1.0 - (xx + zz), yz - wx,
                     xz - wy, yz + wx, 1.0 - (xx + yy)], axis=1).reshape(-1, 3, 3)


_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)


class RigidPartsBag(Bag):
    """A bag made of rigid bodies `self.parts` whose centres sit at `self.offsets` (bag frame)."""
    parts: list[int]
    offsets: np.ndarray

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.constraints: list[int] = []
        self._twists: list[tuple] = []
        self._local_corners = None
        self._invalidate()

    def _invalidate(self) -> None:
        """The part poses changed (stepped, set, restored): drop the per-step reads."""
        self._memo = None
        self._corners = None

    @property
    def body_ids(self) -> list[int]:
        return list(self.parts)

    def set_pose(self, position, orientation) -> None:
        q = rot.normalize(np.asarray(orientation, dtype=float))
        for b, off in zip(self.parts, self.offsets):
            self.p.resetBasePositionAndOrientation(
                b, (np.asarray(position) + rot.rotate(q, off)).tolist(), q.tolist(),
                physicsClientId=self.client)
            self.p.resetBaseVelocity(b, [0, 0, 0], [0, 0, 0], physicsClientId=self.client)
        self._invalidate()

    def part_for_handle(self, k: int) -> int:
        """Index of the part holding handle k (nearest the handle point)."""
        d = np.linalg.norm(self.offsets - self.handle_point(k), axis=1)
        return int(d.argmin())

    def p2p(self, robot, part: int, world_point, max_force: float) -> int:
        """A point-to-point constraint between the robot's gripper and `part` at a world point."""
        p, c = self.p, self.client
        link = robot.links["gripper"]
        ls = p.getLinkState(robot.id, link, computeForwardKinematics=True, physicsClientId=c)
        body = self.parts[part]
        bp, bq = p.getBasePositionAndOrientation(body, physicsClientId=c)
        cid = p.createConstraint(robot.id, link, body, -1, p.JOINT_POINT2POINT, [0, 0, 0],
                                 to_frame(ls[0], ls[1], world_point), to_frame(bp, bq, world_point),
                                 physicsClientId=c)
        p.changeConstraint(cid, maxForce=max_force, physicsClientId=c)
        self.constraints.append(cid)
        return cid

    def hold_handle(self, k: int, robot, part: int, max_force: float, clamp=None) -> None:
        """Tie handle k to the robot's gripper as the grasp model says (astrobee_sim.grasp):
        strap one point-to-point constraint at the grasp point + the twist spring (before_step),
        hinge two along the strap, each with half of the handle's force budget `max_force`;
        clamp: `clamp()` when the model gives one (its own pre-grasp-model hold), else a fixed
        constraint."""
        joint = self.grasp_model.joint(self.strap_axis(k))
        if joint.fixed and clamp is not None:
            clamp()
            return
        st = self.state()
        hp = self.handle_point(k)
        if joint.fixed:
            self.fixed(robot, part, st.position + rot.rotate(st.orientation, hp), max_force)
        else:
            for off in joint.points:
                wp = st.position + rot.rotate(st.orientation, hp + np.asarray(off))
                self.p2p(robot, part, wp, max_force / len(joint.points))
        if joint.twist_stiffness or joint.twist_damping:
            p, c = self.p, self.client
            ls = p.getLinkState(robot.id, robot.links["gripper"], computeForwardKinematics=True,
                                physicsClientId=c)
            _, qp = p.getBasePositionAndOrientation(self.parts[part], physicsClientId=c)
            axis_w = rot.rotate(st.orientation, self.strap_axis(k))
            normal_w = rot.rotate(st.orientation, self.handles[k])
            self._twists.append((robot, part,
                                 rot.rotate_inverse(np.asarray(qp), axis_w),       # part frame
                                 rot.rotate_inverse(np.asarray(ls[5]), axis_w),    # gripper frame
                                 rot.rotate_inverse(np.asarray(ls[5]), normal_w),
                                 joint.twist_stiffness, joint.twist_damping))

    def fixed(self, robot, part: int, world_point, max_force: float) -> int:
        """A fixed constraint between the robot's gripper and `part` at a world point."""
        p, c = self.p, self.client
        link = robot.links["gripper"]
        ls = p.getLinkState(robot.id, link, computeForwardKinematics=True, physicsClientId=c)
        body = self.parts[part]
        bp, bq = p.getBasePositionAndOrientation(body, physicsClientId=c)
        rel = rot.multiply(rot.conjugate(np.asarray(ls[1])), np.asarray(bq))
        cid = p.createConstraint(robot.id, link, body, -1, p.JOINT_FIXED, [0, 0, 0],
                                 to_frame(ls[0], ls[1], world_point), to_frame(bp, bq, world_point),
                                 parentFrameOrientation=rel.tolist(), physicsClientId=c)
        p.changeConstraint(cid, maxForce=max_force, physicsClientId=c)
        self.constraints.append(cid)
        return cid

    def before_step(self, dt: float) -> None:
        """The strap's twist spring: torque -(k angle + c rate) about the handle normal on the
        bag part, its reaction on the gripper (astrobee_sim.grasp.twist_forces' rule)."""
        if not self._twists:
            return
        p, c = self.p, self.client
        for robot, part, u_part, u_grip, n_grip, k, cd in self._twists:
            link = robot.links["gripper"]
            ls = p.getLinkState(robot.id, link, computeLinkVelocity=1,
                                computeForwardKinematics=1, physicsClientId=c)
            body = self.parts[part]
            _, qp = p.getBasePositionAndOrientation(body, physicsClientId=c)
            wp = p.getBaseVelocity(body, physicsClientId=c)[1]
            qg = np.asarray(ls[5])
            n = rot.rotate(qg, n_grip)
            u = rot.rotate(qg, u_grip)
            e = rot.rotate(np.asarray(qp), u_part)
            ep = e - np.dot(e, n) * n
            ang = np.arctan2(np.dot(np.cross(u, ep), n), np.dot(u, ep))
            rate = np.dot(np.subtract(wp, ls[7]), n)
            tau = (-(k * ang + cd * rate) * n).tolist()
            p.applyExternalTorque(body, -1, tau, p.WORLD_FRAME, physicsClientId=c)
            p.applyExternalTorque(robot.id, link, [-t for t in tau], p.WORLD_FRAME,
                                  physicsClientId=c)

    def release(self) -> None:
        for cid in self.constraints:
            self.p.removeConstraint(cid, physicsClientId=self.client)
        self.constraints = []
        self._twists = []
        self.attached = [False] * len(self.handles)
        self._invalidate()

    def _poses(self):
        """(P, Q, V, W) of the parts, read once per physics step (state() and points() share it)."""
        if self._memo is None:
            p, c = self.p, self.client
            pose, vel = p.getBasePositionAndOrientation, p.getBaseVelocity
            P, Q, V, W = [], [], [], []
            for b in self.parts:
                pos, q = pose(b, physicsClientId=c)
                v, w = vel(b, physicsClientId=c)
                P.append(pos); Q.append(q); V.append(v); W.append(w)
            self._memo = (np.array(P), np.array(Q), np.array(V), np.array(W))
        return self._memo

    def after_step(self, dt: float, sample: bool = True) -> None:
        self._invalidate()

    def state(self) -> BagState:
        P, Q, V, W = self._poses()
        if len(self.parts) == 1:
            q = Q[0]
            return BagState(P[0] - qrot(q, self.offsets[0]), q.copy(), V[0].copy(), W[0].copy(),
                            0.0, list(self.attached))
        q, c = kabsch(self.offsets, P)
        R = quat_matrices(q[None])[0]
        mean_off = self.offsets.mean(axis=0)
        pos = c - R @ mean_off
        v = V.mean(axis=0)
        r = P - c
        # least-squares omega from the parts' relative velocities (v_i - v = omega x r_i):
        # normal equations sum(|r|^2 I - r r^T) omega = sum r x (v_i - v)
        J = np.eye(3) * np.einsum("ij,ij->", r, r) - r.T @ r
        w = np.linalg.solve(J, np.cross(r, V - v).sum(axis=0))
        rest = c + (self.offsets - mean_off) @ R.T
        deform = float(np.sqrt(np.mean(np.sum((P - rest) ** 2, axis=1))))
        return BagState(pos, q, v, w, deform, list(self.attached))

    def points(self) -> np.ndarray:
        """Corners of every part."""
        if self._corners is None:
            P, Q = self._poses()[:2]
            if self._local_corners is None:
                self._local_corners = np.array([_CORNERS * h for h in self.half_extents])
            if len(self.parts) == 1:        # one C call beats the vectorised formula here
                R = np.array(self.p.getMatrixFromQuaternion(Q[0].tolist())).reshape(3, 3)
                self._corners = P[0] + self._local_corners[0] @ R.T
            else:
                R = quat_matrices(Q)                               # (n, 3, 3)
                self._corners = (P[:, None, :] + np.einsum("nkj,nij->nki", self._local_corners, R)
                                 ).reshape(-1, 3)
        return self._corners

    def snapshot(self):
        return None   # rigid parts are covered by the simulation's saveState

    def restore(self, snap) -> None:
        self._invalidate()      # the caller's restoreState moved the parts
