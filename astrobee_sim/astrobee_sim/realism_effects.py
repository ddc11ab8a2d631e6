"""The realism knobs (astrobee.realism.Realism) applied to a pybullet Simulation.

`RealismEffects` is built with the world (Simulation._build) when a knob is on, and holds:
- the EKF error model: a per-run constant bias per robot (drawn once from the seed) plus white
  noise drawn from a generator keyed by (seed, robot, physics step count), so the noise of a
  sample depends on the seed and the sim time only, not on who reads when;
- the actuation model: per-axis multiplicative noise on the held command (redrawn each 16 ms
  control period, keyed by seed, robot and period), then the flight mode's clip, then a first-
  order lag (exact discretisation, alpha = 1 - exp(-dt / tau)) whose state is the applied wrench;
- the disturbance schedule: each pulse's start time and force resolved from the seed at build,
  applied for round(duration / dt) physics steps (impulse = force x that many steps x dt) and
  logged when it starts (`log`).
Only `step()` here runs when actuation or disturbances are on; Simulation.step keeps its own
loop, untouched, otherwise. The FEM bag integrated by pybullet (fem_solver bullet) takes no
external force in pybullet 3.2.7, so a bag pulse on it is applied as a uniform gravity field
over the pulse, the robots' links compensated by opposite forces (net zero on them).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from astrobee import rotations as rot
from astrobee.realism import Realism
from astrobee.scenario import ScenarioError

CONTROL_PERIOD = 0.016        # s: the actuation noise is redrawn once per control period
_BIAS, _EKF, _ACT, _DIST = 0, 1, 2, 3     # independent random streams of one seed


def _rng(*key: int) -> np.random.Generator:
    return np.random.default_rng([int(k) for k in key])


def bag_params(model: str, base: dict[str, Any], realism: Realism) -> dict[str, Any]:
    """Bag-model keywords scaling its stiffness and damping (see Realism's docstring)."""
    s, d = realism.bag_stiffness_scale, realism.bag_damping_scale
    out: dict[str, Any] = {}
    if model == "fem":
        if s != 1.0:
            out["elastic_stiffness"] = float(base.get("elastic_stiffness", 50.0)) * s
        if d != 1.0:
            out["damping"] = float(base.get("damping", 0.1)) * d
    elif model == "constraint" and s != 1.0:
        out["max_force"] = float(base.get("max_force", 2.5)) * s
    elif model == "composite" and s != 1.0:
        out["max_force"] = float(base.get("max_force", 20.0)) * s
    return out


class RealismEffects:
    """Realism of one built world (see the module docstring)."""

    def __init__(self, realism: Realism, seed: int, robot_names: list[str], dt: float,
                 has_bag: bool, bag_solver: str | None = None) -> None:
        self.realism = r = realism
        self.seed = int(seed)
        self.dt = float(dt)
        self.names = list(robot_names)
        self.index = {n: i for i, n in enumerate(self.names)}
        self.hold = max(1, int(round(CONTROL_PERIOD / self.dt)))
        self.alpha = 1.0 - math.exp(-self.dt / r.propulsion_lag) if r.propulsion_lag > 0 else 1.0
        self.bias: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for n, i in self.index.items():
            g = _rng(self.seed, _BIAS, i)
            self.bias[n] = (g.normal(0.0, 1.0, 3) * r.ekf_position_bias,
                            g.normal(0.0, 1.0, 3) * r.ekf_attitude_bias)
        self._applied = {n: [0.0] * 6 for n in self.names}   # plain floats: runs every step
        self._noise: dict[str, tuple[int, np.ndarray]] = {}
        self.pulses = self._schedule(has_bag, bag_solver)
        self.log: list[dict] = []

    # ---- disturbances -------------------------------------------------------------------
    def _schedule(self, has_bag: bool, bag_solver: str | None) -> list[dict]:
        """Each pulse: start step, end step, force, target, robot (resolved from the seed)."""
        out = []
        for i, d in enumerate(self.realism.disturbances):
            g = _rng(self.seed, _DIST, i)
            t = d.time if d.time is not None else float(g.uniform(d.t_min, d.t_max))
            if d.force is not None:
                f = np.asarray(d.force, dtype=float)
            else:
                u = g.normal(0.0, 1.0, 3)
                f = d.magnitude * u / np.linalg.norm(u)
            robot = d.robot
            if d.target == "robot":
                if robot not in self.index:
                    if robot or not self.names:
                        raise ScenarioError(f"realism disturbance {i}: no robot {robot!r} in the "
                                            f"scenario (robots: {self.names})")
                    robot = self.names[0]
            k0 = int(round(t / self.dt))
            k1 = k0 + max(1, int(round(d.duration / self.dt)))
            skip = "no bag" if d.target == "bag" and not has_bag else ""
            out.append({"index": i, "k0": k0, "k1": k1, "force": f, "target": d.target,
                        "robot": robot if d.target == "robot" else "", "skip": skip})
        return out

    def schedule(self) -> list[dict]:
        """The resolved pulses as YAML-able data (time, duration, force, target, robot)."""
        return [{"time": p["k0"] * self.dt, "duration": (p["k1"] - p["k0"]) * self.dt,
                 "target": p["target"], "robot": p["robot"], "force": p["force"].tolist(),
                 **({"skipped": p["skip"]} if p["skip"] else {})} for p in self.pulses]

    # ---- EKF ----------------------------------------------------------------------------
    def ekf(self, robot: str, steps: int, state: tuple) -> tuple:
        """The truth state with this robot's bias and the noise of physics step `steps`."""
        r = self.realism
        pos, q, v, w = state
        bp, ba = self.bias[robot]
        n = _rng(self.seed, _EKF, self.index[robot], steps).normal(0.0, 1.0, 12)
        pos = pos + bp + n[0:3] * r.ekf_position_noise
        dq = ba + n[3:6] * r.ekf_attitude_noise
        if dq.any():
            q = rot.normalize(rot.multiply(q, rot.from_rotvec(dq)))
        v = v + n[6:9] * r.ekf_velocity_noise
        w = w + n[9:12] * r.ekf_omega_noise
        return pos, q, v, w

    # ---- actuation ----------------------------------------------------------------------
    @property
    def applied(self) -> dict[str, np.ndarray]:
        """Each robot's wrench applied over the last step (body frame [f, tau])."""
        return {n: np.array(a) for n, a in self._applied.items()}

    def wrench(self, robot: str, r: Any, steps: int) -> list[float]:
        """The wrench applied over physics step `steps`: noisy, clipped, lagged command."""
        target = r.wrench_cmd
        sigma = self.realism.actuation_noise
        if sigma:
            block = steps // self.hold
            cached = self._noise.get(robot)     # (block, command, mode, factor, noisy target)
            if cached is None or cached[0] != block:
                f = 1.0 + sigma * _rng(self.seed, _ACT, self.index[robot], block).normal(0.0, 1.0, 6)
                cached = (block, None, None, f, None)
            if cached[1] is not target or cached[2] is not r.mode:    # a new command or mode
                lim = np.concatenate([r.mode.max_force, r.mode.max_torque])
                cached = (block, target, r.mode, cached[3],
                          np.clip(target * cached[3], -lim, lim).tolist())
            self._noise[robot] = cached
            t = cached[4]
        else:
            t = r._force + r._torque             # the held command as floats (robot.py)
        if self.alpha == 1.0:                   # no lag: the (noisy, clipped) command exactly
            a = self._applied[robot] = list(t)
        else:
            al = self.alpha
            a = self._applied[robot] = [x + al * (y - x) for x, y in zip(self._applied[robot], t)]
        return a

    # ---- stepping -----------------------------------------------------------------------
    def step(self, sim: Any, n: int) -> None:
        """Simulation.step with actuation noise, lag and disturbances (same watchdog)."""
        p, c = sim.p, sim.client
        robots = list(sim.robots.items())
        bag = sim.bag
        for i in range(n):
            k = sim.steps
            sim._watchdog()
            for name, r in robots:
                w = self.wrench(name, r, k)
                if any(w):
                    p.applyExternalForce(r.id, -1, w[:3], r._com_in_base, p.LINK_FRAME,
                                         physicsClientId=c)
                    p.applyExternalTorque(r.id, -1, w[3:], p.LINK_FRAME, physicsClientId=c)
                if r.drag:
                    r.apply(zero=True)
            gravity = self._pulses(sim, k)
            if bag is not None:
                bag.before_step(sim.dt)
            p.stepSimulation(physicsClientId=c)
            if gravity:
                p.setGravity(0, 0, 0, physicsClientId=c)
            sim.time += sim.dt
            sim.steps += 1
            if bag is not None:
                bag.after_step(sim.dt, sample=i >= n - 2)
                if getattr(bag, "external", None) is not None:
                    bag.external = None

    def _pulses(self, sim: Any, k: int) -> bool:
        """Apply the pulses active over step k; True when a gravity field was set for it."""
        gravity = False
        for pz in self.pulses:
            if not pz["k0"] <= k < pz["k1"]:
                continue
            if k == pz["k0"]:
                self.log.append({"time": k * self.dt, "duration": (pz["k1"] - pz["k0"]) * self.dt,
                                 "target": pz["target"], "robot": pz["robot"],
                                 "force": pz["force"].tolist(),
                                 "impulse": (pz["force"] * (pz["k1"] - pz["k0"]) * self.dt).tolist(),
                                 "applied": not pz["skip"], **({"skipped": pz["skip"]} if pz["skip"] else {})})
            if pz["skip"]:
                continue
            f = pz["force"]
            if pz["target"] == "robot":
                self._push_body(sim, sim.robots[pz["robot"]].id, f)
            else:
                gravity |= self._push_bag(sim, f)
        return gravity

    @staticmethod
    def _push_body(sim: Any, body: int, f: np.ndarray) -> None:
        p, c = sim.p, sim.client
        pos, _ = p.getBasePositionAndOrientation(body, physicsClientId=c)
        p.applyExternalForce(body, -1, f.tolist(), list(pos), p.WORLD_FRAME, physicsClientId=c)

    def _push_bag(self, sim: Any, f: np.ndarray) -> bool:
        """Force f on the bag, spread over its mass; True if done by a gravity field."""
        bag = sim.bag
        if hasattr(bag, "parts"):                          # rigid parts: by part mass
            p, c = sim.p, sim.client
            masses = [p.getDynamicsInfo(b, -1, physicsClientId=c)[0] for b in bag.parts]
            total = sum(masses)
            for b, m in zip(bag.parts, masses):
                self._push_body(sim, b, f * (m / total))
            return False
        if hasattr(bag, "external"):                       # fast FEM: per node, equal masses
            ext = np.broadcast_to(f / bag.num_nodes, (bag.num_nodes, 1, 3))
            bag.external = ext if bag.external is None else bag.external + ext
            return False
        # Bullet soft body: gravity f / m_bag on every node, the robots held by -m_link g
        p, c = sim.p, sim.client
        g = f / bag.mass
        p.setGravity(*g.tolist(), physicsClientId=c)
        for r in sim.robots.values():
            for link in range(-1, p.getNumJoints(r.id, physicsClientId=c)):
                m = p.getDynamicsInfo(r.id, link, physicsClientId=c)[0]
                if link == -1:
                    at = p.getBasePositionAndOrientation(r.id, physicsClientId=c)[0]
                else:
                    at = p.getLinkState(r.id, link, physicsClientId=c)[0]
                p.applyExternalForce(r.id, link, (-m * g).tolist(), list(at), p.WORLD_FRAME,
                                     physicsClientId=c)
        return True

    # ---- snapshot -----------------------------------------------------------------------
    def snapshot(self) -> dict:
        return {"applied": {n: list(a) for n, a in self._applied.items()}, "log": len(self.log)}

    def restore(self, snap: dict) -> None:
        for n, a in snap["applied"].items():
            self._applied[n] = list(a)
        del self.log[snap["log"]:]
        self._noise.clear()
