"""The FEM bag integrated by our own solver (mass_spring) beside the pybullet robots and walls.

Same tet mesh, mass and spring material as the Bullet soft body (fem.py), with no pybullet body
for the bag: after each pybullet step the bag takes one semi-implicit step with its handle held
at the gripper's new pose as the grasp model says (astrobee_sim.grasp: strap = the handle
patch's centroid on a stiff implicit spring + a twist spring, hinge = two centroids, clamp =
every patch node on its own spring), then collides its nodes with the
station's wall slabs and the robots' body boxes. Forces go both ways: the anchor springs' pull on
the gripper and the robots' contact reactions are applied to the robots in pybullet before the
next step (`before_step`). The whole bag state is a few numpy arrays, so snapshot/restore is
exact (positions and velocities), unlike pybullet's soft bodies.
"""
from __future__ import annotations

import numpy as np

from astrobee import config
from astrobee import rotations as rot

from .base import Bag, BagState, quat_from_matrix
from ..grasp import twist_weights
from .mass_spring import Anchors, MassSpring, Tethers, Twists
from .mesh import bag_mesh
from .node_contacts import collide_moving_boxes, collide_static_boxes, grow_boxes


def quat_matrices(q: np.ndarray) -> np.ndarray:
    """(K, 3, 3) rotation matrices of quaternions (K, 4) [x,y,z,w]."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], 1)


def best_fit_rotation(rest_centred: np.ndarray, cur_centred: np.ndarray) -> np.ndarray:
    """Rotation matrix taking centred rest points onto centred current points (Kabsch)."""
    U, _, Vt = np.linalg.svd(rest_centred.T @ cur_centred)
    R = Vt.T @ U.T
    if np.linalg.det(R) < 0:
        Vt[2] *= -1
        R = Vt.T @ U.T
    return R


def robot_box_half() -> np.ndarray:
    """Half extents of the robot's collision box (body + propulsion modules), body frame."""
    cfg = config.astrobee()
    bs, ps, py = cfg["body_size"], cfg["propulsion_module_size"], cfg["propulsion_module_y"]
    return 0.5 * np.array([max(bs[0], ps[0]), 2 * py + ps[1], max(bs[2], ps[2])])


class FastFemBag(Bag):
    """fem bag, solver "fast": see the module docstring."""
    model = "fem"
    solver_name = "fast"

    def __init__(self, client: int, variant: str = "front", size=None, mass=None,
                 resolution: int | None = None, walls: np.ndarray | None = None, **params):
        super().__init__(client, variant, size, mass, **params)
        res = int(resolution or self.params.get("resolution", 400))
        self.mesh = bag_mesh(self.size, self.handles, res, self.handle_length, self.handle_height)
        self.num_nodes = len(self.mesh.nodes)
        # Bullet's bending springs are left out unless fast_bending_springs (bags.yaml: they
        # move the bag < 1 mm in Bullet itself and cost ~25% of our step)
        bending = (float(self.params.get("bending_stiffness", 0.1))
                   if self.params.get("fast_bending_springs", False) else 0.0)
        self.springs = MassSpring(self.mesh.nodes, self.mesh.tets, self.mass,
                                  float(self.params.get("elastic_stiffness", 50.0)),
                                  float(self.params.get("damping", 0.1)), bending,
                                  str(self.params.get("damping_mode", "spring")),
                                  int(self.params.get("damping_iterations", 1)))
        if walls is None:
            from ..world import sim_defaults, station
            walls = station(float(sim_defaults().get("wall_thickness", 0.25))).walls
        self.walls = np.asarray(walls, dtype=float)
        self.friction = float(self.params.get("friction", 0.5))
        self.margin = float(self.params.get("collision_margin", 0.006))
        self._walls_grown = grow_boxes(self.walls, self.margin)
        self.half = robot_box_half()
        self._rest_mean = self.mesh.nodes.mean(axis=0)
        self._rest_centred = self.mesh.nodes - self._rest_mean
        self.id = -1                                  # no pybullet body
        self.x = np.ascontiguousarray(self.mesh.nodes[:, None, :].copy())
        self.v = np.zeros_like(self.x)
        self._t = 0.0
        self._grasps: list[dict] = []                 # robot, nodes, offsets (gripper frame)
        self._anchors: Anchors | None = None
        self._tethers: Tethers | None = None
        self._twists: Twists | None = None            # the straps' twist springs
        self._target = self._target_vel = None
        self._tether_target = self._tether_vel = None
        self._pending: list = []                      # per robot: (id, link, F, at, tau, Fc, com, tauc)
        self._state: BagState | None = None
        self.last_penetration = 0.0
        self.external: np.ndarray | None = None       # (N, 1, 3) N per node over the next step

    @property
    def body_ids(self) -> list[int]:
        return []

    # ---- geometry and grasp ----------------------------------------------------------------
    def nodes(self) -> np.ndarray:
        return self.x[:, 0, :].copy()

    def points(self) -> np.ndarray:
        return self.x[:, 0, :]

    def set_pose(self, position, orientation) -> None:
        self.x[:, 0, :] = np.asarray(position) + rot.rotate(np.asarray(orientation), self.mesh.nodes)
        self.v[...] = 0.0
        self._state = None

    def _gripper(self, robot) -> tuple:
        """Gripper link: frame position, frame rotation matrix, COM position, COM velocity, omega."""
        p = self.p
        ls = p.getLinkState(robot.id, robot.links["gripper"], computeLinkVelocity=1,
                            computeForwardKinematics=1, physicsClientId=self.client)
        R = np.array(p.getMatrixFromQuaternion(ls[5])).reshape(3, 3)
        return np.array(ls[4]), R, np.array(ls[0]), np.array(ls[6]), np.array(ls[7])

    def grasp(self, k: int, robot) -> None:
        """Tie handle k as the grasp model says (astrobee_sim.grasp): per-node springs, centroid
        springs on node groups, the twist spring; every point fixed in the gripper frame."""
        hold = self.grasp_model.fem_hold(self.mesh.nodes, np.asarray(self.mesh.handle_nodes[k]),
                                         self.handle_point(k), self.strap_axis(k))
        pos, R, _, _, _ = self._gripper(robot)
        x = self.x[:, 0, :]
        g = {"robot": robot, "hold": hold,
             "offsets": (x[hold.anchors] - pos) @ R,                  # gripper frame
             "tether_offsets": np.array([x[t].mean(axis=0) - pos for t in hold.tethers]
                                        ).reshape(-1, 3) @ R}
        g["all_offsets"] = np.vstack([g["offsets"], g["tether_offsets"]])
        if hold.twist is not None:
            a, b = hold.twist
            e = x[a].mean(axis=0) - x[b].mean(axis=0)
            st = self._pose_now()
            n = rot.rotate(st, self.handles[k])
            g["u"] = (e / np.linalg.norm(e)) @ R
            g["n"] = n @ R
            g["nu"] = np.vstack([g["n"], g["u"]])        # rows: normal, rest axis (gripper frame)
            g["tw"] = twist_weights(self.num_nodes, a, b)
        self._grasps.append(g)
        self._rebuild_anchors()
        self._targets()

    def _pose_now(self) -> np.ndarray:
        """Bag orientation from the nodes (no velocity bookkeeping)."""
        x = self.x[:, 0, :]
        return quat_from_matrix(best_fit_rotation(self._rest_centred, x - x.mean(axis=0)))

    def attach(self, robots: list) -> None:
        self._contact_robots = list(robots)          # every robot's body collides with the bag
        super().attach(robots)

    def release(self) -> None:
        self._grasps = []
        self._anchors = None
        self._tethers = None
        self._twists = None
        self._tether_target = self._tether_vel = None
        self._pending = []
        self.attached = [False] * len(self.handles)

    def _rebuild_anchors(self) -> None:
        holds = [g["hold"] for g in self._grasps]
        nodes = np.concatenate([h.anchors for h in holds]).astype(int)
        ka = np.concatenate([np.full(len(h.anchors), h.anchor_stiffness) for h in holds])
        ca = np.concatenate([np.full(len(h.anchors), h.anchor_damping) for h in holds])
        self._anchors = Anchors(nodes, ka, ca)
        groups = [t for h in holds for t in h.tethers]
        self._tethers = Tethers(groups, np.array([h.tether_stiffness for h in holds
                                                  for _ in h.tethers]),
                                np.array([h.tether_damping for h in holds for _ in h.tethers])
                                ) if groups else None
        twisted = [h for h in holds if h.twist is not None]
        self._twists = Twists([h.twist for h in twisted],
                              np.array([h.twist_stiffness for h in twisted]),
                              np.array([h.twist_damping for h in twisted])) if twisted else None

    def _targets(self) -> list:
        """Anchor and tether targets and their velocities from the grippers' current state;
        returns per grasp (gripper COM, gripper rotation, gripper omega)."""
        tgt, vel, ttg, tvel, grip = [], [], [], [], []
        for g in self._grasps:
            pos, R, com, vcom, w = self._gripper(g["robot"])
            t = pos + g["all_offsets"] @ R.T               # anchors, then tethers: one product
            tv = vcom + np.cross(w, t - com)
            na = len(g["offsets"])
            tgt.append(t[:na])
            vel.append(tv[:na])
            ttg.append(t[na:])
            tvel.append(tv[na:])
            grip.append((com, R, w))
        self._target = np.concatenate(tgt)[:, None, :]
        self._target_vel = np.concatenate(vel)[:, None, :]
        self._tether_target = np.concatenate(ttg)[:, None, :]
        self._tether_vel = np.concatenate(tvel)[:, None, :]
        return grip

    # ---- stepping --------------------------------------------------------------------------
    def before_step(self, dt: float) -> None:
        """Apply the bag's pull on each gripper and its contact push on each robot body."""
        p, c = self.p, self.client
        for rid, link, f, at, tau, fc, com, tc in self._pending:
            if f is not None:
                p.applyExternalForce(rid, link, f, at, p.WORLD_FRAME, physicsClientId=c)
                p.applyExternalTorque(rid, link, tau, p.WORLD_FRAME, physicsClientId=c)
            if fc is not None:
                p.applyExternalForce(rid, -1, fc, com, p.WORLD_FRAME, physicsClientId=c)
                p.applyExternalTorque(rid, -1, tc, p.WORLD_FRAME, physicsClientId=c)

    def after_step(self, dt: float, sample: bool = True) -> None:
        """One bag step after the robots' pybullet step, then the forces for the next one."""
        self._t += dt
        x, v = self.x, self.v
        grip = self._targets() if self._grasps else []
        frames = None
        if self._twists is not None:          # per twist: normal, rest axis, gripper omega
            frames = np.empty((len(self._twists.halves), 1, 9))
            t = 0
            for g, (_, R, w) in zip(self._grasps, grip):
                if g["hold"].twist is not None:
                    frames[t, 0, :6] = (g["nu"] @ R.T).ravel()
                    frames[t, 0, 6:] = w
                    t += 1
        x_prev = x.copy()
        taus = self.springs.step(x, v, dt, self._anchors, self._target, self._target_vel,
                                 self.external, self._tethers, self._tether_target,
                                 self._tether_vel, self._twists, frames)
        taus = iter(() if taus is None else taus[:, 0])
        twist_tau = [next(taus) if g["hold"].twist is not None else None for g in self._grasps]
        flat_x, flat_v = x.reshape(-1, 3), v.reshape(-1, 3)
        self.last_penetration = collide_static_boxes(flat_x, flat_v, x_prev.reshape(-1, 3),
                                                     self.walls, self.margin, self.friction,
                                                     self._walls_grown)
        robots = getattr(self, "_contact_robots", None) or self.robots or []
        pending = []
        skip = self._held_nodes()
        for r in robots:
            pos, q, vel, w = r.state()
            rmat = np.array(self.p.getMatrixFromQuaternion(q.tolist())).reshape(1, 3, 3)
            fc, tc = collide_moving_boxes(
                x, v, x_prev, pos[None], rmat, vel[None], w[None], self.half,
                self.margin, self.friction, self.springs.node_mass, dt, skip)
            pending.append([r.id, None, None, None, None,
                            fc[0].tolist() if fc.any() else None, pos.tolist(), tc[0].tolist()])
        if self._grasps:
            fa = (self.springs.anchor_forces(x, v, self._anchors, self._target,
                                             self._target_vel)[:, 0]
                  if len(self._anchors.nodes) else np.zeros((0, 3)))
            ft = (self.springs.tether_forces(x, v, self._tethers, self._tether_target,
                                             self._tether_vel)[:, 0]
                  if self._tethers is not None else np.zeros((0, 3)))
            sa = st = 0
            for g, (com, _, _), tt in zip(self._grasps, grip, twist_tau):
                na, nt = len(g["hold"].anchors), len(g["hold"].tethers)
                fi = np.concatenate([fa[sa:sa + na], ft[st:st + nt]])
                ti = np.concatenate([self._target[sa:sa + na, 0], self._tether_target[st:st + nt, 0]])
                sa, st = sa + na, st + nt
                torque = np.cross(ti - com, fi).sum(axis=0)
                if tt is not None:
                    torque = torque + tt
                k = robots.index(g["robot"]) if g["robot"] in robots else None
                entry = pending[k] if k is not None else [g["robot"].id, None, None, None, None,
                                                          None, None, None]
                entry[1] = g["robot"].links["gripper"]
                entry[2] = fi.sum(axis=0).tolist()
                entry[3] = com.tolist()
                entry[4] = torque.tolist()
                if k is None:
                    pending.append(entry)
        self._pending = pending
        self._state = None

    def _held_nodes(self) -> np.ndarray | None:
        """Nodes that never collide with the robots: every handle node held by a grasp."""
        if not self._grasps:
            return None
        memo = getattr(self, "_held_memo", None)
        if memo is None or memo[0] is not self._anchors:
            held = [g["hold"].anchors for g in self._grasps]
            held += [t for g in self._grasps for t in g["hold"].tethers]
            memo = self._held_memo = (self._anchors, np.unique(np.concatenate(held)).astype(int))
        return memo[1]

    # ---- state -----------------------------------------------------------------------------
    def state(self) -> BagState:
        if self._state is not None:
            return self._state
        x, v = self.x[:, 0, :], self.v[:, 0, :]
        rest_c = self._rest_centred
        c = x.mean(axis=0)
        r = x - c
        R = best_fit_rotation(rest_c, r)                  # as base.kabsch, rest pre-centred
        q = quat_from_matrix(R)
        vel = v.mean(axis=0)
        # angular momentum sum r x (v - vel) = sum r x v - (sum r) x vel, and sum r = 0
        L = np.array([np.dot(r[:, 1], v[:, 2]) - np.dot(r[:, 2], v[:, 1]),
                      np.dot(r[:, 2], v[:, 0]) - np.dot(r[:, 0], v[:, 2]),
                      np.dot(r[:, 0], v[:, 1]) - np.dot(r[:, 1], v[:, 0])])
        rtr = r.T @ r
        inertia = np.eye(3) * np.trace(rtr) - rtr
        w = np.linalg.solve(inertia, L)
        dev = r - rest_c @ R.T
        deform = float(np.sqrt(np.einsum("ij,ij->", dev, dev) / len(x)))
        pos = c - R @ self._rest_mean
        self._state = BagState(pos, q, vel, w, deform, list(self.attached))
        return self._state

    def snapshot(self):
        return {"x": self.x.copy(), "v": self.v.copy(), "t": self._t,
                "pending": [[list(e) if isinstance(e, list) else e for e in row]
                            for row in self._pending],
                "target": None if self._target is None else self._target.copy(),
                "target_vel": None if self._target_vel is None else self._target_vel.copy(),
                "tether_target": None if self._tether_target is None else self._tether_target.copy(),
                "tether_vel": None if self._tether_vel is None else self._tether_vel.copy()}

    def restore(self, snap) -> None:
        """Exact: node positions, velocities and the forces pending for the robots."""
        self.x[...] = snap["x"]
        self.v[...] = snap["v"]
        self._t = snap["t"]
        self._pending = [[list(e) if isinstance(e, list) else e for e in row]
                         for row in snap["pending"]]
        self._target = None if snap["target"] is None else snap["target"].copy()
        self._target_vel = None if snap["target_vel"] is None else snap["target_vel"].copy()
        self._tether_target = None if snap["tether_target"] is None else snap["tether_target"].copy()
        self._tether_vel = None if snap["tether_vel"] is None else snap["tether_vel"].copy()
        self._state = None
