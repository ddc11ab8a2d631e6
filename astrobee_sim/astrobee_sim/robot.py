"""Astrobee in pybullet: a URDF generated from config/astrobee.yaml, wrench clipping and the arm.

Mass model: the 9.58 kg of FACTS.md is the whole platform, arm included; the body link gets the
rest (9.58 - 0.69 kg) and its inertia is chosen so the whole robot with the arm stowed has the
FACTS inertia about its centre of mass (diagonal part; the arm's products of inertia, ~1e-4 kg m^2,
are left out). The body's collision shape is one box covering body + propulsion modules (the
0.32 m envelope): pybullet's soft-body collision needs convex shapes. The arm links collide
too (so a gripper cannot drag an anchored bag handle into a wall); the fingers do not.
"""
from __future__ import annotations

import math
import os
import tempfile

import numpy as np

from astrobee import config, flight_modes
from astrobee import rotations as rot

# Arm geometry (own approximation): link lengths (m) and mass split of the 0.69 kg arm.
PROXIMAL_LEN = 0.10
DISTAL_LEN = 0.06
GRIPPER_LEN = 0.08
ARM_MASSES = {"proximal": 0.30, "distal": 0.20, "gripper": 0.15, "finger": 0.02}
MAX_ABS_WRENCH = 100.0   # N or N m: anything larger is a bad command, not a saturation
# the arm's moving joints (their positions: Robot.arm_joints), and (parent link, child link) of
# every arm joint, the fixed gripper mount included: what /tf carries per tick (arm_transforms)
ARM_JOINTS = ("arm_proximal_joint", "arm_distal_joint", "finger_left_joint", "finger_right_joint")
ARM_LINKS = (("body", "arm_proximal"), ("arm_proximal", "arm_distal"), ("arm_distal", "gripper"),
             ("gripper", "finger_left"), ("gripper", "finger_right"))


def qrot_floats(q, v) -> tuple[float, float, float]:
    """Rotate one 3-vector by one quaternion [x,y,z,w], in plain floats (~20x faster than numpy
    for a single vector; this runs several times per physics step and per published tick)."""
    x, y, z, w = q
    vx, vy, vz = v
    tx, ty, tz = 2 * (y * vz - z * vy), 2 * (z * vx - x * vz), 2 * (x * vy - y * vx)
    return (vx + w * tx + y * tz - z * ty, vy + w * ty + z * tx - x * tz,
            vz + w * tz + x * ty - y * tx)


_MOUNT: list = []


def arm_transforms(joints) -> list[tuple[float, ...]]:
    """The transforms (x, y, z, qx, qy, qz, qw) parent -> child of the arm's joints (ARM_LINKS
    order) at the moving joints' positions (proximal, distal in rad; left, right finger in m),
    from the URDF's joint origins and axes as robot_state_publisher computes them."""
    if not _MOUNT:
        arm = config.astrobee()["arm"]
        _MOUNT.extend([tuple(float(v) for v in arm["mount_xyz"]),
                       tuple(float(v) for v in rot.from_euler(*arm["mount_rpy"]))])
    (mx, my, mz), (ax, ay, az, aw) = _MOUNT
    a, b, left, right = joints
    sy, cy = math.sin(a / 2), math.cos(a / 2)          # about the mount frame's y
    sz, cz = math.sin(b / 2), math.cos(b / 2)          # about z
    fx = GRIPPER_LEN * 0.6
    return [(mx, my, mz, ax * cy - az * sy, aw * sy + ay * cy, ax * sy + az * cy, aw * cy - ay * sy),
            (PROXIMAL_LEN, 0.0, 0.0, 0.0, 0.0, sz, cz),
            (DISTAL_LEN, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
            (fx, left, 0.0, 0.0, 0.0, 0.0, 1.0),
            (fx, -right, 0.0, 0.0, 0.0, 0.0, 1.0)]


def qrot(q, v) -> np.ndarray:
    """qrot_floats as an array."""
    return np.array(qrot_floats(q, v))


def _box_inertia(m: float, size) -> list[float]:
    x, y, z = size
    return [m * (y * y + z * z) / 12, m * (x * x + z * z) / 12, m * (x * x + y * y) / 12]


def _inertial(m: float, xyz, I) -> str:
    return (f'<inertial><origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}"/><mass value="{m}"/>'
            f'<inertia ixx="{I[0]}" iyy="{I[1]}" izz="{I[2]}" ixy="0" ixz="0" iyz="0"/></inertial>')


def _box(size, xyz=(0, 0, 0), rgba=None, collision=True) -> str:
    g = f'<geometry><box size="{size[0]} {size[1]} {size[2]}"/></geometry>'
    o = f'<origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}"/>'
    s = f'<visual>{o}{g}'
    if rgba:
        s += f'<material name="m{abs(hash(tuple(rgba))) % 10000}"><color rgba="{" ".join(map(str, rgba))}"/></material>'
    s += '</visual>'
    if collision:
        s += f'<collision>{o}{g}</collision>'
    return s


def urdf(body_mass: float, body_com, body_inertia) -> str:
    """The Astrobee URDF text (base link `body`, arm links proximal/distal/gripper, two fingers)."""
    cfg = config.astrobee()
    arm = cfg["arm"]
    bs, ps, py = cfg["body_size"], cfg["propulsion_module_size"], cfg["propulsion_module_y"]
    env = [max(bs[0], ps[0]), 2 * py + ps[1], max(bs[2], ps[2])]
    body = ('<link name="body">' + _inertial(body_mass, body_com, body_inertia)
            + _box(bs, rgba=[0.9, 0.9, 0.9, 1], collision=False)
            + _box(ps, (0, py, 0), rgba=[0.2, 0.4, 0.8, 1], collision=False)
            + _box(ps, (0, -py, 0), rgba=[0.2, 0.4, 0.8, 1], collision=False)
            + f'<collision><geometry><box size="{env[0]} {env[1]} {env[2]}"/></geometry></collision>'
            + '</link>')
    m, r = arm["mount_xyz"], arm["mount_rpy"]
    pl, dl = arm["proximal_limits"], arm["distal_limits"]
    v = arm["joint_speed"]
    A = ARM_MASSES
    s = f'<?xml version="1.0"?><robot name="astrobee">{body}'
    # Deployed (0 rad) the arm points along the mount frame's +x (the body's -x: out of the aft).
    s += ('<link name="arm_proximal">'
          + _inertial(A["proximal"], (PROXIMAL_LEN / 2, 0, 0), _box_inertia(A["proximal"], (PROXIMAL_LEN, .03, .03)))
          + _box((PROXIMAL_LEN, 0.03, 0.03), (PROXIMAL_LEN / 2, 0, 0), [0.3, 0.3, 0.3, 1]) + '</link>')
    s += (f'<joint name="arm_proximal_joint" type="revolute"><parent link="body"/><child link="arm_proximal"/>'
          f'<origin xyz="{m[0]} {m[1]} {m[2]}" rpy="{r[0]} {r[1]} {r[2]}"/><axis xyz="0 1 0"/>'
          f'<limit lower="{pl[0]}" upper="{pl[1]}" effort="2.0" velocity="{v}"/></joint>')
    s += ('<link name="arm_distal">'
          + _inertial(A["distal"], (DISTAL_LEN / 2, 0, 0), _box_inertia(A["distal"], (DISTAL_LEN, .03, .03)))
          + _box((DISTAL_LEN, 0.03, 0.03), (DISTAL_LEN / 2, 0, 0), [0.4, 0.4, 0.4, 1]) + '</link>')
    s += (f'<joint name="arm_distal_joint" type="revolute"><parent link="arm_proximal"/><child link="arm_distal"/>'
          f'<origin xyz="{PROXIMAL_LEN} 0 0"/><axis xyz="0 0 1"/>'
          f'<limit lower="{dl[0]}" upper="{dl[1]}" effort="2.0" velocity="{v}"/></joint>')
    s += ('<link name="gripper">'
          + _inertial(A["gripper"], (GRIPPER_LEN / 2, 0, 0), _box_inertia(A["gripper"], (GRIPPER_LEN, .04, .02)))
          + _box((GRIPPER_LEN * 0.6, 0.04, 0.02), (GRIPPER_LEN * 0.3, 0, 0), [0.2, 0.2, 0.2, 1]) + '</link>')
    s += (f'<joint name="gripper_mount" type="fixed"><parent link="arm_distal"/><child link="gripper"/>'
          f'<origin xyz="{DISTAL_LEN} 0 0"/></joint>')
    gmax = float(arm["gripper_open"]) / 2
    for side, sign in (("left", 1), ("right", -1)):
        s += (f'<link name="finger_{side}">'
              + _inertial(A["finger"], (GRIPPER_LEN * 0.2, 0, 0), _box_inertia(A["finger"], (GRIPPER_LEN * .4, .005, .015)))
              + _box((GRIPPER_LEN * 0.4, 0.005, 0.015), (GRIPPER_LEN * 0.2, 0, 0), [0.1, 0.1, 0.1, 1], False) + '</link>')
        s += (f'<joint name="finger_{side}_joint" type="prismatic"><parent link="gripper"/><child link="finger_{side}"/>'
              f'<origin xyz="{GRIPPER_LEN * 0.6} 0 0"/><axis xyz="0 {sign} 0"/>'
              f'<limit lower="0" upper="{gmax}" effort="5.0" velocity="0.05"/></joint>')
    return s + '</robot>'


class Robot:
    """One Astrobee in a pybullet client: pose/twist in the body frame, clipped wrench, arm."""

    def __init__(self, client: int, name: str = "", position=(0, 0, 0), orientation=(0, 0, 0, 1),
                 flight_mode: str | None = None, drag: bool = False):
        from .pybullet_import import pybullet
        p = pybullet()
        self.p, self.client, self.name = p, client, name
        cfg = config.astrobee()
        self.cfg = cfg
        self.mass = float(cfg["mass"])
        self.inertia = np.asarray(cfg["inertia"], dtype=float)
        self.com_body = np.asarray(cfg["com_offset"], dtype=float)   # whole robot, body frame
        self.drag = drag
        self.drag_k = 0.5 * cfg["air_density"] * cfg["drag_coefficient"] * cfg["drag_area"]
        self.mode = flight_modes.get(flight_mode)
        arm_mass = sum(ARM_MASSES.values()) + ARM_MASSES["finger"]
        self.body_mass = self.mass - arm_mass
        path = self._write(urdf(self.body_mass, self.com_body, (self.inertia * 0.9).tolist()))
        try:
            self.id = p.loadURDF(path, flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=client)
        finally:
            os.unlink(path)
        self.joints = {p.getJointInfo(self.id, j, physicsClientId=client)[1].decode(): j
                       for j in range(p.getNumJoints(self.id, physicsClientId=client))}
        self.links = {p.getJointInfo(self.id, j, physicsClientId=client)[12].decode(): j
                      for j in self.joints.values()}
        for j in range(-1, p.getNumJoints(self.id, physicsClientId=client)):
            p.changeDynamics(self.id, j, linearDamping=0, angularDamping=0,
                             physicsClientId=client)
        self.arm_targets = {"arm_proximal_joint": cfg["arm"]["stowed"]["proximal"],
                            "arm_distal_joint": cfg["arm"]["stowed"]["distal"]}
        self.gripper_target = 0.0
        self._set_joints_now()
        self._fit_inertia()
        self._lim_mode = None
        self.wrench_cmd = np.zeros(6)      # body frame, after clipping
        self._com_in_base = (self.com_body - self.body_com_offset).tolist()
        self.set_pose(position, orientation)

    @staticmethod
    def _write(text: str) -> str:
        fd, path = tempfile.mkstemp(suffix=".urdf", prefix="astrobee_")
        with os.fdopen(fd, "w") as f:
            f.write(text)
        return path

    def _set_joints_now(self) -> None:
        for jn, q in self.arm_targets.items():
            self.p.resetJointState(self.id, self.joints[jn], q, 0.0, physicsClientId=self.client)
        for f in ("finger_left_joint", "finger_right_joint"):
            self.p.resetJointState(self.id, self.joints[f], self.gripper_target, 0.0,
                                   physicsClientId=self.client)
        self._motors()

    def _motors(self) -> None:
        p = self.p
        js = [self.joints[j] for j in self.arm_targets]
        p.setJointMotorControlArray(self.id, js, p.POSITION_CONTROL,
                                    targetPositions=list(self.arm_targets.values()),
                                    forces=[2.0, 2.0], positionGains=[0.3, 0.3],
                                    physicsClientId=self.client)
        fs = [self.joints["finger_left_joint"], self.joints["finger_right_joint"]]
        p.setJointMotorControlArray(self.id, fs, p.POSITION_CONTROL,
                                    targetPositions=[self.gripper_target] * 2, forces=[5.0, 5.0],
                                    physicsClientId=self.client)

    def _fit_inertia(self) -> None:
        """Body-link inertia so the whole robot (arm stowed) has the configured COM inertia."""
        p, c = self.p, self.client
        p.resetBasePositionAndOrientation(self.id, [0, 0, 0], [0, 0, 0, 1], physicsClientId=c)
        base_pos = np.array(p.getBasePositionAndOrientation(self.id, physicsClientId=c)[0])
        local = np.array(p.getDynamicsInfo(self.id, -1, physicsClientId=c)[3])
        origin = base_pos - local                        # body frame origin in world
        parts = []
        for link in self.links.values():
            ls = p.getLinkState(self.id, link, physicsClientId=c)
            info = p.getDynamicsInfo(self.id, link, physicsClientId=c)
            R = rot.to_matrix(np.array(ls[1]))
            parts.append((info[0], np.array(ls[0]) - origin, R @ np.diag(info[2]) @ R.T))
        m_arm = sum(m for m, _, _ in parts)
        com_arm = sum(m * x for m, x, _ in parts) / m_arm
        # body COM such that the whole COM sits at com_body
        body_com = (self.mass * self.com_body - m_arm * com_arm) / self.body_mass
        I_target = np.diag(self.inertia)
        I_arm = sum(Ii + m * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
                    for m, x, Ii in parts for d in [x - self.com_body])
        d = body_com - self.com_body
        I_body = I_target - I_arm - self.body_mass * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
        self.body_com_offset = body_com
        # pybullet cannot move a base's inertial frame after loading: reload with the fitted values
        p.removeBody(self.id, physicsClientId=c)
        path = self._write(urdf(self.body_mass, body_com, np.diag(I_body).tolist()))
        try:
            self.id = p.loadURDF(path, flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=c)
        finally:
            os.unlink(path)
        for j in range(-1, p.getNumJoints(self.id, physicsClientId=c)):
            p.changeDynamics(self.id, j, linearDamping=0, angularDamping=0, physicsClientId=c,
                             activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING)
        self._set_joints_now()
        self.body_inertia_fitted = np.diag(I_body)

    # ---- state -------------------------------------------------------------------------
    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Body-frame origin position and orientation [x,y,z,w] in the world frame."""
        pos, q = self.p.getBasePositionAndOrientation(self.id, physicsClientId=self.client)
        return np.array(pos) - qrot(q, self.body_com_offset), np.array(q)

    def set_pose(self, position, orientation, velocity=(0, 0, 0), omega=(0, 0, 0)) -> None:
        q = rot.normalize(np.asarray(orientation, dtype=float))
        com = np.asarray(position, dtype=float) + rot.rotate(q, self.body_com_offset)
        self.p.resetBasePositionAndOrientation(self.id, com.tolist(), q.tolist(),
                                               physicsClientId=self.client)
        self.p.resetBaseVelocity(self.id, list(velocity), list(omega), physicsClientId=self.client)
        self._set_joints_now()

    def twist(self) -> tuple[np.ndarray, np.ndarray]:
        """World-frame velocity of the body origin and angular velocity (world frame)."""
        return self.state()[2:]

    def state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(pose(), twist()) from one pose and one velocity read, in plain floats (this runs
        every tick; same arithmetic as pose() and np.cross, so bit-identical results)."""
        p, c = self.p, self.client
        pos, q = p.getBasePositionAndOrientation(self.id, physicsClientId=c)
        (vx, vy, vz), w = p.getBaseVelocity(self.id, physicsClientId=c)
        ox, oy, oz = qrot(q, self.body_com_offset).tolist()
        wx, wy, wz = w
        return (np.array((pos[0] - ox, pos[1] - oy, pos[2] - oz)), np.array(q),
                np.array((vx - (wy * oz - wz * oy), vy - (wz * ox - wx * oz), vz - (wx * oy - wy * ox))),
                np.array(w))

    def com(self) -> np.ndarray:
        pos, q = self.pose()
        return pos + rot.rotate(q, self.com_body)

    def gripper_tip(self) -> tuple[np.ndarray, np.ndarray]:
        """World position of the grasp point between the fingers, and the gripper's +x axis."""
        ls = self.p.getLinkState(self.id, self.links["gripper"], computeForwardKinematics=True,
                                 physicsClientId=self.client)
        q = np.array(ls[5])
        pos = np.array(ls[4]) + rot.rotate(q, [GRIPPER_LEN * 0.8, 0, 0])
        return pos, rot.rotate(q, [1.0, 0, 0])

    # ---- commands ----------------------------------------------------------------------
    def set_flight_mode(self, name: str) -> None:
        self.mode = flight_modes.get(name)

    def clip(self, wrench_body: np.ndarray) -> np.ndarray:
        """Clip a body-frame wrench [fx fy fz tx ty tz] per axis to the flight mode's limits."""
        w = np.asarray(wrench_body, dtype=float)
        lim = np.concatenate([self.mode.max_force, self.mode.max_torque])
        return np.clip(w, -lim, lim)

    @staticmethod
    def valid(wrench_body) -> bool:
        """A finite 6-vector with no absurd component (|.| <= 100 N / N m)."""
        w = np.asarray(wrench_body, dtype=float)
        return w.shape == (6,) and bool(np.all(np.isfinite(w))) and bool(np.all(np.abs(w) <= MAX_ABS_WRENCH))

    def command(self, wrench_body) -> bool:
        """Set the body-frame wrench held until the next command; False (ignored) if invalid.

        Same checks as valid() and clipping as clip(), on plain floats (runs every tick)."""
        try:
            w = np.asarray(wrench_body, dtype=float)
        except (TypeError, ValueError):
            return False
        if w.shape != (6,):
            return False
        vals = w.tolist()
        if not all(abs(x) <= MAX_ABS_WRENCH for x in vals):     # NaN and inf fail too
            return False
        if self._lim_mode is not self.mode:
            self._lim_mode = self.mode
            self._lim = np.concatenate([self.mode.max_force, self.mode.max_torque]).tolist()
        self._set_wrench([min(max(x, -lim), lim) for x, lim in zip(vals, self._lim)])
        return True

    @property
    def wrench_cmd(self) -> np.ndarray:
        return self._wrench

    @wrench_cmd.setter
    def wrench_cmd(self, w) -> None:
        self._set_wrench(np.asarray(w, dtype=float).tolist())

    def _set_wrench(self, vals: list[float]) -> None:
        self._wrench = np.array(vals, dtype=float)
        self._force = [float(x) for x in vals[:3]]
        self._torque = [float(x) for x in vals[3:]]
        self._active = any(vals)

    def apply(self, zero: bool = False) -> None:
        """Apply the held wrench for the coming step: body frame (pybullet LINK_FRAME of the
        base), the force at the whole robot's COM; optional quadratic drag in the world frame."""
        p, c = self.p, self.client
        if self._active and not zero:
            p.applyExternalForce(self.id, -1, self._force, self._com_in_base, p.LINK_FRAME,
                                 physicsClientId=c)
            p.applyExternalTorque(self.id, -1, self._torque, p.LINK_FRAME, physicsClientId=c)
        if self.drag:
            v, _ = p.getBaseVelocity(self.id, physicsClientId=c)
            v = np.array(v)
            f = -self.drag_k * np.linalg.norm(v) * v
            pos, _ = p.getBasePositionAndOrientation(self.id, physicsClientId=c)
            p.applyExternalForce(self.id, -1, f.tolist(), list(pos), p.WORLD_FRAME, physicsClientId=c)

    def deploy_arm(self, deployed: bool = True, instant: bool = False) -> None:
        k = "deployed" if deployed else "stowed"
        a = self.cfg["arm"][k]
        self.arm_targets = {"arm_proximal_joint": a["proximal"], "arm_distal_joint": a["distal"]}
        self._set_joints_now() if instant else self._motors()

    def gripper(self, open_: bool, instant: bool = False) -> None:
        self.gripper_target = float(self.cfg["arm"]["gripper_open"]) / 2 if open_ else 0.0
        self._set_joints_now() if instant else self._motors()

    def arm_joints(self) -> tuple[float, ...]:
        """Positions of ARM_JOINTS (rad, rad, m, m): one joint-state query."""
        ids = self.__dict__.get("_arm_ids")
        if ids is None:
            ids = self._arm_ids = [self.joints[j] for j in ARM_JOINTS]
        return tuple(js[0] for js in self.p.getJointStates(self.id, ids, physicsClientId=self.client))

    def joint_positions(self) -> dict[str, float]:
        return {n: self.p.getJointState(self.id, j, physicsClientId=self.client)[0]
                for n, j in self.joints.items() if n != "gripper_mount"}
