"""Gymnasium environments of the cargo transport, on the in-process Flight (no router).

`AstrobeeCargo-v0` (registered when astrobee_lab is imported):

    import gymnasium as gym, astrobee_lab
    env = gym.make("AstrobeeCargo-v0", bag_model="fem", fem_solver="fast", action_mode="residual")

One step is one control tick (62.5 Hz: the simulator advances 5-6 physics steps at 350 Hz).
Action (Box [-1, 1]^6): the body-frame wrench [fx fy fz tx ty tz] as a fraction of the flight
mode's per-axis limits, applied as is (`action_mode="wrench"`) or added to the PD tracker's
wrench (`"residual"`, scaled by `residual_scale`). Observation (float32 vector, OBS_FIELDS):
the robot's EKF state relative to the goal, the reference of this tick, the PD wrench, the bag's
reduced state relative to the robot (centre, velocity, orientation; zeros and flag 0 without a
bag), the time fraction; with `observe_nodes=True` the bag's points (FEM nodes or box corners)
in the robot's body frame as well. Reward, termination (goal reached at rest, a contact, a
fault) and truncation (time limit) are astrobee.task's (at rest: under `rest_speed` m/s and
`rest_omega` rad/s, looser than the PD law's own test by default). `reset(seed=...)` makes a rollout
reproducible; `random_start_goal=True` draws the start and the goal in the planner's safe set.
`render_mode="rgb_array"` draws the chase + overview frame of astrobee_sim.render.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from astrobee import rotations as rot
from astrobee.scenario import Scenario
from astrobee.task import RewardWeights

from .flight import Flight, FlightObs

ACTION_MODES = ("wrench", "residual")
OBS_FIELDS = (
    ("goal_offset", 3),          # goal position - robot position (world, m)
    ("goal_attitude", 3),        # rotation vector robot -> goal attitude (body, rad)
    ("velocity", 3),             # robot velocity (world, m/s)
    ("orientation", 4),          # robot quaternion [x y z w]
    ("omega", 3),                # robot angular velocity (body, rad/s)
    ("ref_offset", 3),           # reference position - robot position (world, m)
    ("ref_velocity", 3),         # reference velocity (world, m/s)
    ("ref_attitude", 3),         # rotation vector robot -> reference attitude (body, rad)
    ("pd_wrench", 6),            # the PD law's wrench / limits
    ("bag_offset", 3),           # bag centre - robot (body frame, m)
    ("bag_velocity", 3),         # bag velocity - robot velocity (body frame, m/s)
    ("bag_orientation", 4),      # bag orientation relative to the robot's
    ("bag_flag", 1),             # 1 when a bag is held
    ("time_fraction", 1),        # elapsed / time limit
)
OBS_SIZE = sum(n for _, n in OBS_FIELDS)
OBS_BOUND = 1e3          # every field is far inside (m, m/s, rad, fractions)
MAX_DRAWS = 200


class AstrobeeCargoEnv(gym.Env):
    """A robot carrying a bag (any model and variant) along a planned leg (module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 31.25}

    def __init__(self, scenario: str | Scenario = "node2_to_jem_bag", *,
                 bag_model: str | None = None, bag_variant: str | None = None,
                 bag_resolution: int | None = None, bag_mass: float | None = None,
                 fem_solver: str | None = None, flight_mode: str | None = None,
                 realism: Any = None, action_mode: str = "residual",
                 residual_scale: float = 0.25, random_start_goal: bool = False,
                 hop_distance: tuple[float, float] = (0.5, 2.0), observe_nodes: bool = False,
                 time_limit: float | None = None, end_on_contact: bool = True,
                 rest_speed: float = 0.02, rest_omega: float = 0.1,
                 reward_weights: RewardWeights | None = None, render_mode: str | None = None,
                 render_size: tuple[int, int] = (320, 240)) -> None:
        if action_mode not in ACTION_MODES:
            raise ValueError(f"action_mode must be one of {', '.join(ACTION_MODES)}, got {action_mode!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be 'rgb_array' or None, got {render_mode!r}")
        if not 0 < residual_scale <= 1:
            raise ValueError(f"residual_scale must be in (0, 1], got {residual_scale}")
        lo, hi = hop_distance
        if not 0 < lo <= hi:
            raise ValueError(f"hop_distance must be 0 < min <= max, got {hop_distance}")
        # "at rest" looser than the PD law's own test (0.01 m/s, 0.02 rad/s): with the realism
        # knobs on, a robot holding a swinging bag in tolerance keeps moving a little
        task: dict[str, Any] = {"end_on_contact": end_on_contact, "rest_speed": float(rest_speed),
                                "rest_omega": float(rest_omega)}
        if time_limit is not None:
            task["time_limit"] = float(time_limit)
        if reward_weights is not None:
            task["weights"] = reward_weights
        self.flight = Flight(scenario, controller="pd", bag_model=bag_model, bag_variant=bag_variant,
                             bag_resolution=bag_resolution, bag_mass=bag_mass, fem_solver=fem_solver,
                             flight_mode=flight_mode, realism=realism, task=task)
        self.base = self.flight.scenario
        if len(self.flight.names) != 1:
            raise ValueError("AstrobeeCargo-v0 flies one robot; the scenario has "
                             f"{len(self.flight.names)}")
        self.action_mode = action_mode
        self.residual_scale = float(residual_scale)
        self.random_start_goal = bool(random_start_goal)
        self.hop_distance = (float(lo), float(hi))
        self.observe_nodes = bool(observe_nodes)
        self.render_mode = render_mode
        self.render_size = (int(render_size[0]), int(render_size[1]))
        self._renderer: Any = None
        mode = self.flight.mode
        self._limits = np.concatenate([mode.max_force, mode.max_torque]).astype(float)
        self._limits_safe = np.where(self._limits > 0, self._limits, 1.0)
        self.n_nodes = 0
        if self.observe_nodes:
            self.flight.reset(0)           # the bag's point count fixes the observation size
            pts = self.flight.sim.bag_points()
            self.n_nodes = 0 if pts is None else len(pts)
        self.action_space = spaces.Box(-1.0, 1.0, (6,), np.float32)
        self.observation_space = spaces.Box(-OBS_BOUND, OBS_BOUND,
                                            (OBS_SIZE + 3 * self.n_nodes,), np.float32)
        self._obs: FlightObs | None = None

    # ---- episodes ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        rng = self.np_random
        sim_seed = int(rng.integers(0, 2**31 - 1))
        sc = self.base
        for _ in range(MAX_DRAWS if self.random_start_goal else 1):
            if self.random_start_goal:
                sc = self._draw(rng)
            obs = self.flight.reset(sim_seed, scenario=sc)
            if not self.flight.monitor.failure:
                break
        else:
            raise RuntimeError(f"no plannable start/goal found in {MAX_DRAWS} draws")
        if self.flight.monitor.failure:
            raise RuntimeError(f"the episode cannot start: {self.flight.monitor.failure}")
        self._obs = obs
        return self._vector(obs), self._info()

    def _draw(self, rng: np.random.Generator) -> Scenario:
        start, goal = random_start_goal(rng, self.base, self.hop_distance)
        q = self.base.robots[0].orientation
        sc = replace(self.base, name=self.base.name + "_random")
        return sc.with_start_goal((start, q), (goal, q))

    def step(self, action):
        a = np.minimum(np.maximum(np.asarray(action, dtype=float).reshape(6), -1.0), 1.0)
        if self.action_mode == "wrench":
            obs, sample = self.flight.step(a * self._limits, mode="replace")
        else:
            obs, sample = self.flight.step(a * self._limits * self.residual_scale, mode="add")
        m = self.flight.monitor
        reward = m.reward(sample)
        self._obs = obs
        return self._vector(obs), reward, bool(m.terminated), bool(m.truncated), self._info()

    def _info(self) -> dict[str, Any]:
        """t, success and cause (the Task's verdict, at the episode's end only), contacts, seed."""
        m = self.flight.monitor
        ok, cause = m.verdict() if m.terminated or m.truncated else (False, "")
        return {"t": self.flight.sim.time, "success": ok and m.goal_reached, "cause": cause,
                "contacts": m.contact_samples, "seed": self.flight.seed}

    # ---- observation ------------------------------------------------------------------------
    def _vector(self, obs: FlightObs) -> np.ndarray:
        """The observation (OBS_FIELDS, then the bag's points): gathered as floats and clipped
        to OBS_BOUND (once per step: one list, one array, no per-field arrays)."""
        name = self.flight.names[0]
        r = obs.robots[name]
        st, ref = r.state, r.reference
        q = np.asarray(st.orientation, float)
        pos = np.asarray(st.position, float)
        goal = self.flight.task.goals[name]
        vals = [*(goal.position - pos).tolist(), *rot.attitude_error(q, goal.orientation).tolist(),
                *_floats(st.velocity), *q.tolist(), *_floats(st.omega),
                *(ref.position - pos).tolist(), *_floats(ref.velocity),
                *rot.attitude_error(q, ref.orientation).tolist(),
                *(r.nominal / self._limits_safe).tolist()]
        bag = obs.bag
        r_wb = rot.to_matrix(q)                       # body -> world, once per tick
        if bag is not None and _held(bag.attached):
            qb = rot.normalize(bag.orientation)
            vals += [*((np.asarray(bag.position) - pos) @ r_wb).tolist(),
                     *((np.asarray(bag.velocity) - st.velocity) @ r_wb).tolist(),
                     *rot.multiply(rot.conjugate(q), qb).tolist(), 1.0]
        else:
            vals += [0.0] * 6 + [0.0, 0.0, 0.0, 1.0, 0.0]
        m = self.flight.monitor
        vals.append(min((m.t - m.t0) / self.flight.task.time_limit, 1.0))
        if self.n_nodes:
            out = np.zeros(self.observation_space.shape[0], np.float64)
            out[:OBS_SIZE] = vals
            pts = self.flight.sim.bag_points()
            if pts is not None and len(pts) == self.n_nodes:
                rel = (np.asarray(pts, float) - pos) @ r_wb     # body frame
                out[OBS_SIZE:] = rel.ravel()
        else:
            out = np.array(vals, np.float64)
            if out.shape != (OBS_SIZE,):
                raise ValueError(f"observation has {out.size} values, OBS_FIELDS say {OBS_SIZE}")
        # np.clip's arithmetic without its Python-level dispatch
        np.maximum(out, -OBS_BOUND, out=out)
        return np.minimum(out, OBS_BOUND, out=out).astype(np.float32)

    # ---- rendering --------------------------------------------------------------------------
    def render(self):
        if self.render_mode != "rgb_array" or self._obs is None:
            return None
        from astrobee_sim import render as rd
        w, h = self.render_size
        if self._renderer is None:
            self._renderer = rd.FlightRenderer((w - h, h), (h, h), self.flight.sim.world)
        sim, name = self.flight.sim, self.flight.names[0]
        scene = rd.Scene(robots=[(sim.robot_state(n)[0], sim.robot_state(n)[1])
                                 for n in self.flight.names], arm_deployed=sim.bag is not None)
        pts = sim.bag_points()
        if pts is not None:
            mesh = getattr(sim.bag, "mesh", None)
            if mesh is not None:
                faces = rd.boundary_faces(mesh.tets)
            elif len(pts) % 8 == 0:
                faces = rd.box_surface(pts)[1]
            else:
                faces = rd.hull_faces(pts)
            scene.bag = rd.Surface(np.asarray(pts, float), faces)
        traj = self.flight.traj
        path = traj.position if traj is not None else np.asarray([sim.robot_state(name)[0]])
        if traj is not None:
            scene.lines.append(rd.Polyline(traj.position))
        m = self.flight.monitor
        scene.text = [f"t {m.t - m.t0:5.1f} s  {self.action_mode}", f"contacts {m.contact_samples}"]
        heading = sim.robot_state(name)[2]
        overview = rd.overview_camera(np.vstack([path, self.flight.task.goals[name].position]))
        return self._renderer.render(scene, heading, overview)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        self.flight.close()


def _floats(v: Any) -> list[float]:
    """A 3-vector (array, list or tuple) as a list of floats."""
    return np.asarray(v, float).ravel().tolist()


def _held(attached: Any) -> bool:
    """Whether any grasp holds the bag (`attached`: a bool or one per robot)."""
    if isinstance(attached, (list, tuple)):
        return any(bool(a) for a in attached)
    return bool(np.any(np.asarray(attached, bool)))


def random_start_goal(rng: np.random.Generator, scenario: Scenario,
                      distance: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """A start and a goal in the planner's safe set (shrunk by the robot and the carried bag's
    margin), `distance` m apart; with a bag both keep an extra 0.6 m from the walls (the bag
    hangs beside the robot and the scenario's orientation is kept)."""
    from astrobee_planning import planner
    safe = planner.cached_safe_set(scenario.carry_extent if scenario.carrying_bag else 0.0)
    extra = 0.6 if scenario.carrying_bag else 0.0
    boxes = np.asarray(safe.boxes, float).copy()
    boxes[:, :3] += extra
    boxes[:, 3:] -= extra
    boxes = boxes[np.all(boxes[:, 3:] > boxes[:, :3], axis=1)]
    if not len(boxes):
        raise ValueError("no room in the safe set for a random start")
    vol = np.prod(boxes[:, 3:] - boxes[:, :3], axis=1)
    p = vol / vol.sum()

    def point() -> np.ndarray:
        b = boxes[rng.choice(len(boxes), p=p)]
        return b[:3] + rng.random(3) * (b[3:] - b[:3])

    lo, hi = distance
    for _ in range(MAX_DRAWS):
        start = point()
        for _ in range(20):
            d = rng.normal(size=3)
            goal = start + d / np.linalg.norm(d) * rng.uniform(lo, hi)
            inside = np.any(np.all((goal >= boxes[:, :3]) & (goal <= boxes[:, 3:]), axis=1))
            if inside:
                return start, goal
    raise ValueError(f"no start/goal pair {lo}..{hi} m apart found in {MAX_DRAWS} draws")
