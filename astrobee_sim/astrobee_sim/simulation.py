"""The simulation without transport: ISS walls + Astrobee(s) + an optional cargo bag in pybullet.

One pybullet client per Simulation (DIRECT by default); one of sim_node's backends (backend.py).
The world is built from a typed `astrobee.scenario.Scenario` (loaded once with the overrides);
a reset request is validated whole before the running world is cleared. `step()` advances one physics step with
the held, clipped body-frame wrenches; the propulsion watchdog zeroes a robot's wrench when no
command came for `watchdog_timeout` seconds. Deterministic for a given scenario, seed and
command sequence.

Realism knobs (astrobee.realism; the scenario's `realism:` or the `realism=` override): the
world is built with them and realism_effects.RealismEffects applies them: `ekf_state()` is the
noisy, biased estimate (robot_state() stays the truth), `told_bag_mass()` the mass a controller
is told, `step()` adds actuation noise, propulsion lag and disturbance pulses
(`disturbance_log`). With every knob off none of it runs and nothing changes.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from astrobee import config, flight_modes
from astrobee.flight_modes import FlightMode
from astrobee.overrides import Overrides
from astrobee.realism import Realism
from astrobee.realism import resolve as resolve_realism
from astrobee.scenario import Scenario, ScenarioError

from .backend import BagInfo, Contact, check_seed, resolve_scenario, standing_overrides
from .bags import Bag, BagState, make_bag
from .realism_effects import RealismEffects, bag_params
from .robot import Robot
from .world import build_pybullet, sim_defaults, station

__all__ = ["Contact", "ScenarioError", "Simulation"]


class Simulation:
    """World + robots + bag, stepped at `physics_rate` Hz."""

    def __init__(self, scenario: str | Scenario = "node2_to_jem", seed: int = 0,
                 physics_rate: float | None = None, gui: bool = False, drag: bool = False,
                 wall_thickness: float | None = None, wall_bodies: int = 16,
                 overrides: Overrides | None = None,
                 grasp: str | None = None, **keys: Any):
        """scenario: a name in config/scenarios (loaded with the overrides, which also apply to
        later resets by name) or a Scenario as is. The overrides: an astrobee.overrides.Overrides
        or its keys as keywords (bag_model=..., robots=..., realism=...); realism (a preset
        name, a mapping of knobs or a Realism) replaces the scenario's also for later resets, a
        Scenario given whole included.
        grasp: the bag's grasp model (astrobee_sim.grasp; strap | hinge | clamp) replacing the
        scenario's, likewise. Raises ScenarioError for a bad scenario, realism or seed before pybullet is started."""
        self.overrides = standing_overrides(overrides, keys)
        realism = self.overrides.realism
        self._realism = None if realism is None else resolve_realism(realism)
        self._grasp = grasp or None
        sc = self._resolve(scenario, None)
        seed = check_seed(seed)
        defaults = sim_defaults()
        self.dt = 1.0 / float(physics_rate or defaults.get("physics_rate", 350.0))
        wall_thickness = float(wall_thickness or defaults.get("wall_thickness", 0.25))
        from .pybullet_import import pybullet
        p = pybullet()
        self.p = p
        self.client = p.connect(p.GUI if gui else p.DIRECT)
        self.gui = gui
        self.drag = drag
        self.world = station(wall_thickness)
        self.wall_bodies = wall_bodies
        self.watchdog_timeout = float(config.astrobee().get("watchdog_timeout", 0.32))
        self._half_envelope = float(config.astrobee().get("envelope", 0.32)) / 2
        self.robots: dict[str, Robot] = {}
        self.bag: Bag | None = None
        self.scenario: Scenario | None = None
        self.effects: RealismEffects | None = None
        self.reset(sc, seed)

    # ---- setup ---------------------------------------------------------------------------
    @property
    def scenario_name(self) -> str:
        return self.scenario.name

    def reset(self, scenario: str | Scenario | None = None, seed: int | None = None) -> None:
        """Rebuild the world from a scenario (None/'': the current one) and a seed (None: the
        current one). The request is validated first: a bad one raises ScenarioError and leaves
        the running world as it was."""
        sc = self._resolve(scenario, self.scenario)
        seed = check_seed(getattr(self, "seed", 0) if seed is None else seed)
        self._build(sc, seed)

    def _resolve(self, scenario: str | Scenario | None, current: Scenario | None) -> Scenario:
        """resolve_scenario, the standing realism override applied to a Scenario given whole."""
        sc = resolve_scenario(scenario, current, self.overrides)
        forced = self._realism
        if forced is not None and sc.realism != forced:
            sc = sc.override(realism=forced)
        if self._grasp and sc.bag is not None and sc.bag.grasp != self._grasp:
            bag = replace(sc.bag, grasp=self._grasp)
            bag.validate()
            sc = replace(sc, bag=bag)
        return sc

    def _build(self, sc: Scenario, seed: int) -> None:
        p, c = self.p, self.client
        bag = sc.bag
        fem = bag is not None and bag.model == "fem"
        soft = fem and bag.solver == "bullet"        # a pybullet soft body
        # built (and checked: robot names of disturbances) before the old world is cleared
        effects = (RealismEffects(sc.realism, seed, sc.robot_names, self.dt, bag is not None)
                   if sc.realism.physical else None)
        p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD if soft else 0, physicsClientId=c)
        p.setGravity(0, 0, 0, physicsClientId=c)
        p.setTimeStep(self.dt, physicsClientId=c)
        if self.gui:
            p.configureDebugVisualizer(p.COV_ENABLE_RENDERING, 0, physicsClientId=c)
        # soft bodies collide properly only with plain convex shapes: compound walls let FEM
        # nodes sink through (measured); the rigid models get the cheaper compounds
        self.wall_ids = build_pybullet(self.world, c, visuals=self.gui,
                                       per_body=1 if soft else self.wall_bodies)
        self._wall_set = frozenset(self.wall_ids)
        rng = np.random.default_rng(seed)
        noise = sc.initial_position_noise
        self.robots = {}
        for rs in sc.robots:
            pos = np.asarray(rs.position, dtype=float) + rng.normal(0, noise, 3) * (noise > 0)
            r = Robot(c, rs.name, pos, list(rs.orientation), sc.flight_mode, self.drag)
            self.robots[r.name] = r
        self.bag = None
        if bag is not None:
            for r in self.robots.values():
                r.deploy_arm(True, instant=True)
                r.gripper(False, instant=True)
            kw: dict[str, Any] = {"size": list(bag.size), "mass": bag.mass}
            if fem:
                if bag.resolution:
                    kw["resolution"] = int(bag.resolution)
                kw["solver"] = bag.solver
            kw.update(bag_params(bag.model, config.bags()["models"].get(bag.model, {}), sc.realism))
            kw["grasp"] = bag.grasp
            if sc.realism.handle_stiffness_scale != 1.0:
                kw["handle_stiffness_scale"] = sc.realism.handle_stiffness_scale
            self.bag = make_bag(bag.model, c, bag.variant, **kw)
            self.bag.attach(list(self.robots.values()))
        if self.gui:
            p.configureDebugVisualizer(p.COV_ENABLE_RENDERING, 1, physicsClientId=c)
        self.scenario = sc
        self.seed = seed
        self.flight_mode = flight_modes.get(sc.flight_mode)
        self.time = 0.0
        self.steps = 0
        self._bag_memo = None
        self.last_command = {n: 0.0 for n in self.robots}
        self.fault = {n: False for n in self.robots}
        self.rejected = 0
        self.effects = effects
        self._stepper = effects if effects is not None and sc.realism.affects_stepping else None

    # ---- commands ------------------------------------------------------------------------
    def command(self, wrench_body, robot: str = "") -> bool:
        """Hold a body-frame wrench [fx fy fz tx ty tz] for `robot`; False if rejected."""
        r = self.robots.get(robot)
        if r is None or not r.command(wrench_body):
            self.rejected += 1
            return False
        self.last_command[robot] = self.time
        return True

    def set_flight_mode(self, name: str, robot: str | None = None) -> None:
        """Change one robot's flight mode, or every robot's (raises UnknownFlightMode, or
        KeyError for an unknown robot)."""
        mode = flight_modes.get(name)
        if robot is not None:
            self.robots[robot].set_flight_mode(name)
            return
        self.flight_mode = mode
        for r in self.robots.values():
            r.set_flight_mode(name)

    def flight_mode_of(self, robot: str) -> FlightMode:
        return self.robots[robot].mode

    # ---- stepping ------------------------------------------------------------------------
    def step(self, n: int = 1) -> None:
        """Advance n physics steps (with actuation noise, lag and disturbances when on)."""
        if self._stepper is not None:
            self._stepper.step(self, n)
            return
        p, c = self.p, self.client
        step_sim = p.stepSimulation
        robots = list(self.robots.values())
        bag = self.bag
        for i in range(n):
            self._watchdog()
            for r in robots:
                r.apply()
            if bag is not None:
                bag.before_step(self.dt)
            step_sim(physicsClientId=c)
            self.time += self.dt
            self.steps += 1
            if bag is not None:
                bag.after_step(self.dt, sample=i >= n - 2)

    def _watchdog(self) -> None:
        """The propulsion watchdog at the current time: a robot with no command for
        `watchdog_timeout` s has its held wrench zeroed and is faulted until a command comes."""
        t, last, fault = self.time, self.last_command, self.fault
        limit = self.watchdog_timeout + 1e-9
        for name, r in self.robots.items():
            if t - last[name] > limit:
                if not fault[name]:
                    fault[name] = True
                    r.wrench_cmd = np.zeros(6)
            elif fault[name]:
                fault[name] = False

    def advance(self, duration: float) -> None:
        self.step(max(1, int(round(duration / self.dt))))

    # ---- state ---------------------------------------------------------------------------
    def robot_state(self, robot: str = "") -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(position, orientation [x,y,z,w], velocity, angular velocity), world frame."""
        return self.robots[robot].state()

    def robot_names(self) -> list[str]:
        return list(self.robots)

    def arm_joints(self, robot: str = "") -> tuple[float, ...]:
        """The robot's arm joint positions (robot.ARM_JOINTS: rad, rad, m, m)."""
        return self.robots[robot].arm_joints()

    # ---- realism -------------------------------------------------------------------------
    @property
    def realism(self) -> Realism:
        """The realism knobs in effect (the scenario's, or the override's)."""
        return self.scenario.realism

    def ekf_state(self, robot: str = "") -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """What the robot's EKF would say: robot_state() (same frames) with the localization
        bias and noise of the current physics step; robot_state() itself when they are off."""
        state = self.robots[robot].state()
        e = self.effects
        if e is None or not e.realism.ekf_noisy:
            return state
        return e.ekf(robot, self.steps, state)

    def told_bag_mass(self) -> float:
        """The bag mass a controller is told (true mass x realism bag_mass_told); 0 without a bag."""
        bag = self.scenario.bag
        return 0.0 if bag is None else self.realism.told_mass(bag.mass)

    @property
    def disturbance_log(self) -> list[dict]:
        """The disturbance pulses started so far: time, duration, target, robot, force, impulse."""
        return [] if self.effects is None else list(self.effects.log)

    def disturbance_schedule(self) -> list[dict]:
        """Every pulse of this run as resolved from the seed (started or not)."""
        return [] if self.effects is None else self.effects.schedule()

    def faulted(self, robot: str) -> bool:
        return self.fault[robot]

    def bag_state(self) -> BagState | None:
        return None if self.bag is None else self.bag.state()

    def bag_points(self) -> np.ndarray | None:
        return None if self.bag is None else self.bag.points()

    def bag_info(self) -> BagInfo | None:
        """Model facts of the bag: FEM node count, or the number of rigid parts (fixed for a
        bag: found once per bag, sim_node asks every tick)."""
        b = self.bag
        if b is None:
            return None
        memo = self.__dict__.get("_bag_info")
        if memo is None or memo[0] is not b:
            parts = len(b.points()) if b.model == "fem" else len(b.body_ids)
            memo = self._bag_info = (b, BagInfo(b.model, b.variant, int(parts)))
        return memo[1]

    def contacts(self) -> list[Contact]:
        """Contacts of the robots and the bag with the station walls.

        Rigid bodies: pybullet's contact points (one unfiltered query, split per body as the
        per-body query would: the queried body as A, normal flipped when it was B). FEM nodes
        are not reported by pybullet: a node within 1 cm of a wall counts, one contact (the
        deepest node) per tick.
        """
        p, c = self.p, self.client
        walls = self._wall_set
        named = [(n or "robot", r.id) for n, r in self.robots.items()]
        fem = self.bag is not None and self.bag.model == "fem"
        if self.bag is not None and not fem:
            named += [("bag", b) for b in self.bag.body_ids]
        per_body: dict[int, list] = {}
        for cp in p.getContactPoints(physicsClientId=c):
            a, b = cp[1], cp[2]
            if b in walls:
                per_body.setdefault(a, []).append((cp[5], cp[7], cp[9]))
            elif a in walls:
                n = cp[7]
                per_body.setdefault(b, []).append((cp[6], (-n[0], -n[1], -n[2]), cp[9]))
        out = []
        if per_body:
            for name, body in named:
                for pos, normal, force in per_body.get(body, ()):
                    out.append(Contact(name, "iss", np.array(pos), np.array(normal), float(force)))
        if fem:
            x = self.bag.points()
            d, i = self._bag_nearest()
            if d < 0.01:
                out.append(Contact("bag", "iss", x[i].copy(), np.zeros(3), 0.0))
        return out

    def clearance(self, robot_positions: list | None = None) -> tuple[float, float]:
        """Smallest distance of the robots' envelope and of the bag to a wall (m).

        robot_positions: the robots' current positions in self.robots order when the caller
        already read them this step (saves a pybullet state query per robot)."""
        if not self.robots:
            rc = -1.0
        else:
            pts = np.array(robot_positions if robot_positions is not None
                           else [r.state()[0] for r in self.robots.values()])
            rc = self.world.clearance(pts) - self._half_envelope
        bc = self._bag_nearest()[0] if self.bag is not None else -1.0
        return rc, bc

    def _bag_nearest(self) -> tuple[float, int]:
        """World.nearest of the bag's points, computed once per physics step."""
        memo = getattr(self, "_bag_memo", None)
        if memo is None or memo[0] != self.steps or memo[1] is not self.bag:
            memo = (self.steps, self.bag, self.world.nearest(self.bag.points()))
            self._bag_memo = memo
        return memo[2]

    # ---- snapshot ------------------------------------------------------------------------
    def snapshot(self) -> dict:
        """Whole-world snapshot: rigid bodies via saveState, FEM nodes by the bag itself."""
        sid = self.p.saveState(physicsClientId=self.client)
        return {"state": sid, "bag": None if self.bag is None else self.bag.snapshot(),
                "time": self.time, "steps": self.steps,
                "cmd": {n: r.wrench_cmd.copy() for n, r in self.robots.items()},
                "last": dict(self.last_command), "fault": dict(self.fault),
                "realism": None if self.effects is None else self.effects.snapshot()}

    def restore(self, snap: dict) -> None:
        self.p.restoreState(stateId=snap["state"], physicsClientId=self.client)
        self._bag_memo = None
        if self.bag is not None:
            self.bag.restore(snap["bag"])
        self.time, self.steps = snap["time"], snap["steps"]
        for n, r in self.robots.items():
            r.wrench_cmd = snap["cmd"][n].copy()
        self.last_command = dict(snap["last"])
        self.fault = dict(snap["fault"])
        if self.effects is not None and snap.get("realism") is not None:
            self.effects.restore(snap["realism"])

    def close(self) -> None:
        try:
            self.p.disconnect(physicsClientId=self.client)
        except Exception:   # already gone
            pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
