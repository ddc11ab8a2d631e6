"""A small rigid-body simulator backend (numpy, no pybullet) for graph tests and quick runs.

Each Astrobee is one free rigid body (config/astrobee.yaml mass, inertia, centre of mass) driven
by the held body-frame wrench, clipped per axis to its flight mode's propulsion limits exactly
as the pybullet robot is, with the same propulsion watchdog (no command for `watchdog_timeout`
s: wrench zeroed, fault raised). Integration: semi-implicit Euler, body-frame angular velocity,
exact quaternion update per physics step.

The cargo bag, when the scenario has one, is rigidly attached to the FIRST robot as extra mass:
a box of the bag's size and mass held at that robot's gripper (arm deployed, handle 0 at the
grasp point, as the pybullet placement puts it), folded into that robot's mass, centre of mass
and inertia. Other robots fly alone (a two-handle bag is not shared). There are no wall
collisions: the station (astrobee_sim.world.World) gives clearances, and a robot envelope or a
bag corner past a wall is reported as a contact.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from astrobee import config, flight_modes
from astrobee import rotations as rot
from astrobee.flight_modes import FlightMode
from astrobee.overrides import Overrides
from astrobee.scenario import BagSpec, Scenario

from .backend import BagInfo, Contact, check_seed, resolve_scenario, standing_overrides
from .bags.base import BagState, align
from .robot import DISTAL_LEN, GRIPPER_LEN, MAX_ABS_WRENCH, PROXIMAL_LEN
from .world import sim_defaults, station

_CORNERS = np.array([[sx, sy, sz] for sx in (-0.5, 0.5) for sy in (-0.5, 0.5) for sz in (-0.5, 0.5)])


def _box_inertia(mass: float, size: Any) -> np.ndarray:
    x, y, z = np.asarray(size, dtype=float)
    return mass / 12.0 * np.diag([y * y + z * z, x * x + z * z, x * x + y * y])


def _parallel(mass: float, d: np.ndarray) -> np.ndarray:
    return mass * (float(d @ d) * np.eye(3) - np.outer(d, d))


def bag_mount(bag: BagSpec) -> tuple[np.ndarray, np.ndarray]:
    """(bag centre in the robot body frame, bag -> body rotation quaternion) for a bag held by
    handle 0 at the deployed arm's grasp point (the pybullet placement, without the arm's
    joint dynamics)."""
    arm = config.astrobee()["arm"]
    mount = np.asarray(arm["mount_xyz"], dtype=float)
    # the mount frame is pitched by pi: the deployed arm reaches along the body's -x
    tip = mount + np.array([-(PROXIMAL_LEN + DISTAL_LEN + GRIPPER_LEN * 0.8), 0.0, 0.0])
    g_body = np.array([-1.0, 0.0, 0.0])
    handles = config.bags()["handles"][bag.variant]
    h = np.asarray(handles[0], dtype=float)
    q_rel = align(h, -g_body)
    ax = int(np.argmax(np.abs(h)))
    hp = h * (bag.size[ax] / 2 + float(config.bags().get("handle_height", 0.04)))
    return tip - rot.rotate(q_rel, hp), q_rel


class RigidRobot:
    """One Astrobee as a free rigid body; wrenches in the BODY frame, applied at the robot's
    own centre of mass (as pybullet's robot); state at the body origin (the robot point)."""

    def __init__(self, name: str, position: Any, orientation: Any, mode: FlightMode,
                 bag: BagSpec | None = None) -> None:
        cfg = config.astrobee()
        self.name, self.mode = name, mode
        m_r = float(cfg["mass"])
        c_r = np.asarray(cfg["com_offset"], dtype=float)            # robot COM, body frame
        inertia = np.diag(np.asarray(cfg["inertia"], dtype=float))  # about the robot COM
        self.bag = bag
        if bag is None:
            mass, com = m_r, c_r
            self.bag_offset, self.bag_q = np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])
        else:
            d, q_rel = bag_mount(bag)
            self.bag_offset, self.bag_q = d, q_rel
            mass = m_r + bag.mass
            com = (m_r * c_r + bag.mass * d) / mass
            r = rot.to_matrix(q_rel)
            inertia = (inertia + _parallel(m_r, c_r - com)
                       + r @ _box_inertia(bag.mass, bag.size) @ r.T + _parallel(bag.mass, d - com))
        self.m = mass
        self.c = com                       # body COM relative to the robot point, body frame
        self.arm = c_r - com               # where the thrust acts, relative to the body COM
        self.inertia = inertia
        self.inertia_inv = np.linalg.inv(inertia)
        self.q = rot.normalize(np.asarray(orientation, dtype=float))
        self.x = np.asarray(position, dtype=float) + rot.rotate(self.q, self.c)   # COM, world
        self.v = np.zeros(3)               # COM velocity, world
        self.w = np.zeros(3)               # angular velocity, body frame
        self.wrench = np.zeros(6)

    def command(self, wrench_body: Any) -> bool:
        """Hold a clipped body wrench; False (ignored) for a non-finite, absurd or misshapen one."""
        try:
            w = np.asarray(wrench_body, dtype=float)
        except (TypeError, ValueError):
            return False
        if w.shape != (6,) or not bool(np.all(np.abs(w) <= MAX_ABS_WRENCH)):   # NaN fails too
            return False
        lim = np.concatenate([self.mode.max_force, self.mode.max_torque])
        self.wrench = np.clip(w, -lim, lim)
        return True

    def step(self, dt: float, zero: bool = False) -> None:
        f_b = np.zeros(3) if zero else self.wrench[:3]
        tau = (np.zeros(3) if zero else self.wrench[3:]) + rot.cross(self.arm, f_b)
        self.v = self.v + rot.rotate(self.q, f_b) / self.m * dt
        self.x = self.x + self.v * dt
        wdot = self.inertia_inv @ (tau - rot.cross(self.w, self.inertia @ self.w))
        self.w = self.w + wdot * dt
        self.q = rot.step_body(self.q, self.w * dt)

    def state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(position, orientation, velocity, angular velocity) of the robot point, world frame."""
        r_b = -self.c
        w_world = rot.rotate(self.q, self.w)
        pos = self.x + rot.rotate(self.q, r_b)
        vel = self.v + rot.rotate(self.q, rot.cross(self.w, r_b))
        return pos, self.q.copy(), vel, w_world

    def bag_state(self) -> BagState:
        pos, q, v, w = self.state()
        off = rot.rotate(q, self.bag_offset)
        return BagState(pos + off, rot.multiply(q, self.bag_q), v + rot.cross(w, off), w, 0.0)

    def bag_points(self) -> np.ndarray:
        st = self.bag_state()
        local = _CORNERS * np.asarray(self.bag.size, dtype=float)
        return st.position + local @ rot.to_matrix(st.orientation).T


class RigidSim:
    """The rigid-body SimBackend (see the module docstring); keywords as Simulation's."""

    def __init__(self, scenario: str | Scenario = "node2_to_jem", seed: int = 0,
                 physics_rate: float | None = None, wall_thickness: float | None = None,
                 gui: bool = False, drag: bool = False, overrides: Overrides | None = None,
                 **keys: Any) -> None:
        """The overrides as Simulation's (an Overrides or its keywords); gui and drag are
        accepted and ignored (no viewer, no air drag)."""
        self.overrides = standing_overrides(overrides, keys)
        sc = resolve_scenario(scenario, None, self.overrides)
        seed = check_seed(seed)
        defaults = sim_defaults()
        self.dt = 1.0 / float(physics_rate or defaults.get("physics_rate", 350.0))
        self.world = station(float(wall_thickness or defaults.get("wall_thickness", 0.25)))
        self.watchdog_timeout = float(config.astrobee().get("watchdog_timeout", 0.32))
        self._half_envelope = float(config.astrobee().get("envelope", 0.32)) / 2
        self.scenario: Scenario | None = None
        self.reset(sc, seed)

    # ---- setup ---------------------------------------------------------------------------
    def reset(self, scenario: str | Scenario | None = None, seed: int | None = None) -> None:
        """Rebuild from a scenario and seed; a bad request raises before anything changes."""
        sc = resolve_scenario(scenario, self.scenario, self.overrides)
        seed = check_seed(getattr(self, "seed", 0) if seed is None else seed)
        mode = flight_modes.get(sc.flight_mode)
        rng = np.random.default_rng(seed)
        noise = sc.initial_position_noise
        robots: dict[str, RigidRobot] = {}
        for i, rs in enumerate(sc.robots):
            pos = np.asarray(rs.position, dtype=float) + rng.normal(0, noise, 3) * (noise > 0)
            robots[rs.name] = RigidRobot(rs.name, pos, rs.orientation, mode,
                                         sc.bag if i == 0 else None)
        self.robots = robots
        self.carrier = next(iter(robots.values())) if sc.bag is not None else None
        self.scenario, self.seed = sc, seed
        self.time, self.steps = 0.0, 0
        self.last_command = {n: 0.0 for n in robots}
        self.fault = {n: False for n in robots}
        self.rejected = 0

    # ---- commands ------------------------------------------------------------------------
    def robot_names(self) -> list[str]:
        return list(self.robots)

    def arm_joints(self, robot: str = "") -> tuple[float, ...]:
        """Arm joint positions as the pybullet world sets them: deployed with a bag (each
        robot), stowed without; fingers closed."""
        if robot not in self.robots:
            raise KeyError(robot)
        arm = config.astrobee()["arm"]["deployed" if self.scenario.bag is not None else "stowed"]
        return (float(arm["proximal"]), float(arm["distal"]), 0.0, 0.0)

    def flight_mode_of(self, robot: str) -> FlightMode:
        return self.robots[robot].mode

    def set_flight_mode(self, name: str, robot: str | None = None) -> None:
        mode = flight_modes.get(name)
        for r in ([self.robots[robot]] if robot is not None else self.robots.values()):
            r.mode = mode

    def command(self, wrench_body: Any, robot: str = "") -> bool:
        r = self.robots.get(robot)
        if r is None or not r.command(wrench_body):
            self.rejected += 1
            return False
        self.last_command[robot] = self.time
        return True

    def step(self, n: int = 1) -> None:
        limit = self.watchdog_timeout + 1e-9
        for _ in range(n):
            for name, r in self.robots.items():
                if self.time - self.last_command[name] > limit:
                    if not self.fault[name]:
                        self.fault[name] = True
                        r.wrench = np.zeros(6)
                elif self.fault[name]:
                    self.fault[name] = False
                r.step(self.dt)
            self.time += self.dt
            self.steps += 1

    # ---- state ---------------------------------------------------------------------------
    def robot_state(self, robot: str = "") -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return self.robots[robot].state()

    def faulted(self, robot: str) -> bool:
        return self.fault[robot]

    def bag_info(self) -> BagInfo | None:
        b = self.scenario.bag
        return None if b is None else BagInfo(b.model, b.variant, 1)

    def bag_state(self) -> BagState | None:
        if self.carrier is None:
            return None
        st = self.carrier.bag_state()
        st.attached = [True] + [False] * (len(config.bags()["handles"][self.scenario.bag.variant]) - 1)
        return st

    def bag_points(self) -> np.ndarray | None:
        return None if self.carrier is None else self.carrier.bag_points()

    def clearance(self, robot_positions: list | None = None) -> tuple[float, float]:
        pts = np.array(robot_positions if robot_positions is not None
                       else [r.state()[0] for r in self.robots.values()])
        rc = self.world.clearance(pts) - self._half_envelope
        bc = self.world.clearance(self.bag_points()) if self.carrier is not None else -1.0
        return rc, bc

    def contacts(self) -> list[Contact]:
        """A robot envelope or bag corner past a wall (no collision response here)."""
        out = []
        for name, r in self.robots.items():
            pos = r.state()[0]
            if self.world.clearance(pos[None, :]) - self._half_envelope < 0:
                out.append(Contact(name or "robot", "iss", pos, np.zeros(3), 0.0))
        if self.carrier is not None:
            pts = self.bag_points()
            d, i = self.world.nearest(pts)
            if d < 0:
                out.append(Contact("bag", "iss", pts[i].copy(), np.zeros(3), 0.0))
        return out

    def close(self) -> None:
        """Nothing to free (no external engine)."""
