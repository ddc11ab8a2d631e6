"""The interface every cargo-bag model shares, plus placement and pose-fitting helpers."""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from astrobee import config
from astrobee import rotations as rot

VARIANTS = ("front", "right", "top", "front_back", "right_left", "top_bottom")


class BagError(ValueError):
    """Unknown bag model or variant, or a bag that cannot be attached as asked."""


@dataclass
class BagState:
    position: np.ndarray          # centroid, world frame
    orientation: np.ndarray       # [x,y,z,w], bag frame -> world
    velocity: np.ndarray          # centroid velocity, world frame
    omega: np.ndarray             # angular velocity, world frame
    deformation: float            # RMS node distance from the rest shape at this pose (m)
    attached: list[bool] = field(default_factory=list)


def handle_dirs(variant: str) -> list[np.ndarray]:
    """Handle directions (bag frame) of a variant, from config/bags.yaml."""
    handles = config.bags()["handles"]
    if variant not in VARIANTS or variant not in handles:
        raise BagError(f"unknown bag variant {variant!r}; known: {', '.join(VARIANTS)}")
    return [np.asarray(h, dtype=float) for h in handles[variant]]


def align(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation quaternion taking unit vector a onto unit vector b."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    c = np.cross(a, b)
    d = float(np.dot(a, b))
    if d < -1 + 1e-9:
        ax = np.cross(a, [1.0, 0, 0])
        if np.linalg.norm(ax) < 1e-6:
            ax = np.cross(a, [0, 1.0, 0])
        return rot.from_axis_angle(ax, np.pi)
    return rot.normalize(np.array([*c, 1.0 + d]))


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """[x,y,z,w] of a rotation matrix (Shepperd's method; scipy's is ~50x slower per call)."""
    t = R[0, 0] + R[1, 1] + R[2, 2]
    if t > 0:
        s = 2.0 * np.sqrt(t + 1.0)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s]
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def kabsch(rest: np.ndarray, cur: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Best-fit rotation (quaternion) and centroid taking centred `rest` points onto `cur`."""
    c = cur.mean(axis=0)
    H = (rest - rest.mean(axis=0)).T @ (cur - c)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    R = Vt.T @ np.diag([1, 1, d]) @ U.T
    return quat_from_matrix(R), c


class Bag(ABC):
    """A cargo bag model in a pybullet client.

    Lifecycle: construct (loads bodies at a parking pose), `attach(robots)` places it at the
    first robot's gripper (and a second robot's, for two-handle variants) and grasps;
    `state()` each tick; `snapshot()`/`restore()` for rollouts; `after_step(dt)` after every
    physics step (FEM velocity bookkeeping).
    """
    model = "base"

    def __init__(self, client: int, variant: str = "front", size=None, mass: float | None = None,
                 grasp: str | None = None, handle_stiffness_scale: float = 1.0, **params):
        """grasp: a model of astrobee_sim.grasp (None: bags.yaml's default), its stiffnesses
        times handle_stiffness_scale; BagError for an unknown name."""
        import pybullet as p
        from ..grasp import GraspError, make_grasp
        try:
            self.grasp_model = make_grasp(grasp, handle_stiffness_scale,
                                          stiffness=params.pop("anchor_stiffness", None),
                                          damping=params.pop("anchor_damping", None))
        except GraspError as exc:
            raise BagError(str(exc)) from None
        self.p, self.client = p, client
        cfg = config.bags()
        self.variant = variant
        self.handles = handle_dirs(variant)
        self.size = np.asarray(size if size is not None else cfg["default"]["size"], dtype=float)
        self.mass = float(mass if mass is not None else cfg["default"]["mass"])
        self.handle_height = float(cfg.get("handle_height", 0.04))
        self.handle_length = float(cfg.get("handle_length", 0.12))
        self.params = {**cfg["models"].get(self.model, {}), **params}
        self.attached = [False] * len(self.handles)
        self.robots: list = []

    # ---- geometry ----------------------------------------------------------------------
    def strap_axis(self, k: int) -> np.ndarray:
        """Unit long axis of handle k's strap, bag frame."""
        from ..grasp import strap_axis
        return strap_axis(self.size, self.handles[k])

    def handle_point(self, k: int) -> np.ndarray:
        """Outer grasp point of handle k in the bag frame."""
        h = self.handles[k]
        ax = int(np.argmax(np.abs(h)))
        return h * (self.size[ax] / 2 + self.handle_height)

    def placement(self, robot) -> tuple[np.ndarray, np.ndarray]:
        """Bag pose (centre, orientation) with handle 0 at `robot`'s gripper, facing the robot."""
        tip, g = robot.gripper_tip()
        _, q_r = robot.pose()
        g_body = rot.rotate_inverse(q_r, g)
        q0 = align(self.handles[0], -g_body)
        q = rot.multiply(q_r, q0)
        centre = tip - rot.rotate(q, self.handle_point(0))
        return centre, q

    # ---- interface ---------------------------------------------------------------------
    @property
    @abstractmethod
    def body_ids(self) -> list[int]:
        """pybullet body ids making up the bag (for contact queries)."""

    @abstractmethod
    def set_pose(self, position, orientation) -> None:
        """Put the bag, undeformed and at rest, at a pose."""

    @abstractmethod
    def grasp(self, k: int, robot) -> None:
        """Tie handle k (already at the robot's gripper) to the robot."""

    @abstractmethod
    def release(self) -> None:
        """Remove every grasp."""

    @abstractmethod
    def state(self) -> BagState: ...

    @abstractmethod
    def points(self) -> np.ndarray:
        """World points bounding the bag (nodes or box corners), for clearance checks."""

    @abstractmethod
    def snapshot(self): ...

    @abstractmethod
    def restore(self, snap) -> None: ...

    def before_step(self, dt: float) -> None:
        """Called before every physics step (a bag integrated outside pybullet applies its
        reaction forces on the robots here)."""

    def after_step(self, dt: float, sample: bool = True) -> None:
        """Called after every physics step."""

    def attach(self, robots: list) -> None:
        """Place the bag at robots[0]'s gripper and grasp; robots[1] grasps handle 1 if any."""
        self.release()
        centre, q = self.placement(robots[0])
        self.set_pose(centre, q)
        if len(self.handles) > 1 and len(robots) > 1:
            # the second robot faces the first across the bag, its gripper on handle 1
            r2 = robots[1]
            _, q1 = robots[0].pose()
            q2 = rot.multiply(q1, rot.from_axis_angle([0, 0, 1.0], np.pi))
            r2.set_pose(np.zeros(3), q2)
            tip0, _ = r2.gripper_tip()
            h1 = centre + rot.rotate(q, self.handle_point(1))
            r2.set_pose(h1 - tip0, q2)
        self.robots = list(robots[: len(self.handles)])
        for k, r in enumerate(self.robots):
            self.grasp(k, r)
            self.attached[k] = True

    def handle_world(self, k: int) -> np.ndarray:
        st = self.state()
        return st.position + rot.rotate(st.orientation, self.handle_point(k))

    def ignore_collisions_with(self, body: int) -> None:
        """Disable collisions between the bag's rigid parts and another body (e.g. the robot)."""
        p = self.p
        n_other = p.getNumJoints(body, physicsClientId=self.client)
        for b in self.body_ids:
            for lb in range(-1, p.getNumJoints(b, physicsClientId=self.client)):
                for lo in range(-1, n_other):
                    p.setCollisionFilterPair(b, body, lb, lo, 0, physicsClientId=self.client)
