"""System identification of rollout model A's handle (reduced_model: HandleParams,
PendulumParams, RigidBodyParams) from a bag simulation.

Procedure (bench/sysid_bag.py runs it for every bag model and writes config/reduced_models.yaml):
1. `record`: the PD tracker (tracking.Tracker, told the bag's mass) flies the robot through a
   random sequence of rest-to-rest moves (`excitation`) around its start pose in Node 2 while
   the bag model of a simulator swings behind it; robot and bag states are sampled at 62.5 Hz.
   The simulator is duck-typed (astrobee_sim.Simulation: command/advance/robot_state/bag_state/
   time/flight_mode), so this module never imports it.
2. `fit`: the robot's recorded motion drives the spring-damper alone (handle_models.simulate_bag);
   least squares over log-stiffness, log-damping (3 body axes each) and the rest offset
   minimises the bag-centre position error.
3. `error`: the same prediction on a held-out motion (another seed) gives the identification
   error that is reported (RMS and max of the bag-centre position error, m).
4. `horizon_error`: what the MPC relies on: 5 s closed-loop rollouts of the model (PD law,
   recorded reference) started every 1 s from the recorded state, bag and robot error (world).
   On the FEM bag the robot-bag pair turns (torque-limited Astrobee), which only this error
   sees; `rigid_body` (no fit: the mean offset) wins it 3-4x over the spring (see
   reduced_model's docstring), `fit_pendulum` is kept for the swing about the handle.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from astrobee import rotations as rot

from .handle_models import (HandleParams, PendulumParams, RigidBodyParams, simulate_bag,
                            simulate_pendulum, simulate_pendulums)
from .mass import MassProperties, with_bag
from .mass import robot as robot_mass
from .pd import State
from .reduced_model import CandidateReferences, Gains, ReducedModel, RolloutStart
from .reference import rest_to_rest
from .tracking import Tracker

RATE = 62.5  # Hz, the controller's rate


@dataclass
class Recording:
    """Sampled robot and bag states (world frame) of one excitation run."""

    t: np.ndarray
    robot_position: np.ndarray
    robot_velocity: np.ndarray
    robot_orientation: np.ndarray   # (T, 4) [x,y,z,w]
    bag_position: np.ndarray
    bag_velocity: np.ndarray
    bag_mass: float
    bag_orientation: np.ndarray | None = None   # (T, 4) [x,y,z,w], bag -> world
    bag_omega: np.ndarray | None = None         # (T, 3) rad/s, world frame
    reference: tuple | None = None              # (position, velocity, accel (T, 3), orientation
                                                # (T, 4)): what the tracker followed
    ff_mass: float = 0.0                        # kg, and inertia (3x3): what the PD law was told
    ff_inertia: np.ndarray | None = None
    bag_size: np.ndarray | None = None

    @property
    def rotation(self) -> np.ndarray:
        return np.array([rot.to_matrix(q) for q in self.robot_orientation])

    def body_offsets(self) -> np.ndarray:
        """Bag centre in the robot body frame at each sample (T, 3)."""
        return np.einsum("tji,tj->ti", self.rotation, self.bag_position - self.robot_position)


def excitation(seed: int, moves: int = 6, amplitude=(0.25, 0.25, 0.3),
               durations=(3.0, 6.0)) -> list[tuple[np.ndarray, float]]:
    """A random sequence of (offset from the start position (m), duration (s)) moves."""
    rng = np.random.default_rng(seed)
    amp = np.asarray(amplitude, float)
    return [(rng.uniform(-amp, amp), float(rng.uniform(*durations))) for _ in range(moves)]


def record(sim, robot_mass: MassProperties, moves: list[tuple[np.ndarray, float]],
           hold: float = 1.0, robot: str = "") -> Recording:
    """Fly `moves` (see `excitation`) with the PD tracker in `sim`, sampling at 62.5 Hz."""
    bag = sim.bag
    p0, q0, _, _ = sim.robot_state(robot)
    st = sim.bag_state()
    offset = rot.rotate_inverse(q0, st.position - p0)
    r_rel = rot.to_matrix(q0).T @ rot.to_matrix(st.orientation)
    tracker = Tracker(sim.flight_mode, with_bag(robot_mass, bag.mass, bag.size, offset, r_rel))
    rows: list[tuple] = []
    dt = 1.0 / RATE
    prev = np.asarray(p0, float)
    for off, dur in moves:
        goal = np.asarray(p0, float) + off
        traj = rest_to_rest(prev, goal, q0, q0, dur).shifted(sim.time)
        tracker.follow(traj, sim.time)
        end = sim.time + dur + hold
        while sim.time < end:
            p, q, v, w = sim.robot_state(robot)
            b = sim.bag_state()
            ref = traj.sample(sim.time)   # after its end: the final (rest) state
            rows.append((sim.time, p, v, q, b.position, b.velocity, b.orientation, b.omega,
                         ref.position, ref.velocity, ref.accel, ref.orientation))
            state = State(np.asarray(p), np.asarray(v), np.asarray(q), rot.rotate_inverse(q, w))
            out = tracker.update(state, sim.time, dt).output
            sim.command(np.concatenate([out.force, out.torque]), robot)
            sim.advance(dt)
        prev = goal
    t, rp, rv, rq, bp, bv, bq, bw, fp, fv, fa, fq = (np.array(c, float) for c in zip(*rows))
    ff = tracker.pd.mass
    return Recording(t, rp, rv, rq, bp, bv, float(bag.mass), bq, bw, (fp, fv, fa, fq),
                     float(ff.mass), np.asarray(ff.inertia, float), np.asarray(bag.size, float))


def predict(handle: "HandleParams | PendulumParams", rec: Recording) -> np.ndarray:
    """Bag-centre positions (T, 3) the handle model predicts for a recording's robot motion."""
    if isinstance(handle, RigidBodyParams):   # held rigidly: the offset turned with the robot
        return rec.robot_position + np.einsum("tij,j->ti", rec.rotation, handle.rest_offset)
    sim = simulate_pendulum if isinstance(handle, PendulumParams) else simulate_bag
    x, _ = sim(handle, rec.bag_mass, rec.t, rec.robot_position, rec.robot_velocity,
               rec.rotation, rec.bag_position[0], rec.bag_velocity[0])
    return x


def error(handle: "HandleParams | PendulumParams", rec: Recording) -> dict:
    """Bag-centre position error of the model on a recording: RMS and max (m), and the RMS of
    the bag's own excursion about its mean body-frame offset (what a rigid-offset model misses)."""
    e = np.linalg.norm(predict(handle, rec) - rec.bag_position, axis=1)
    off = rec.body_offsets()
    swing = np.linalg.norm(off - off.mean(axis=0), axis=1)
    return {"rms": float(np.sqrt(np.mean(e**2))), "max": float(e.max()),
            "swing_rms": float(np.sqrt(np.mean(swing**2)))}


def fit(recordings: list[Recording], starts=((1.0, 1.0, 0.1), (30.0, 10.0, 1.0),
                                             (1000.0, 50.0, 1.0))) -> HandleParams:
    """Least-squares handle parameters over recordings (see the module docstring): log
    stiffness and log damping per body axis, the rest offset, and log drag. The problem has
    local minima (a stiff handle fits the mean offset, a soft one the swing): one solve per
    (stiffness, damping, drag) start, the best kept."""
    fits = [_fit_from(recordings, *s) for s in starts]
    return min(fits, key=lambda f: f[1])[0]


def _fit_from(recordings: list[Recording], k0: float, c0: float,
              drag0: float) -> tuple[HandleParams, float]:
    from scipy.optimize import least_squares

    d0 = np.mean([r.body_offsets().mean(axis=0) for r in recordings], axis=0)
    x0 = np.concatenate([np.full(3, np.log(k0)), np.full(3, np.log(c0)), d0, [np.log(drag0)]])

    def unpack(x: np.ndarray) -> HandleParams:
        return HandleParams(np.exp(x[:3]), np.exp(x[3:6]), x[6:9], float(np.exp(x[9])))

    def residuals(x: np.ndarray) -> np.ndarray:
        h = unpack(x)
        return np.concatenate([(predict(h, r) - r.bag_position).ravel() for r in recordings])

    lo = np.concatenate([np.full(6, np.log(1e-2)), d0 - 0.3, [np.log(1e-3)]])
    hi = np.concatenate([np.full(3, np.log(1e5)), np.full(3, np.log(1e4)), d0 + 0.3, [np.log(1e3)]])
    sol = least_squares(residuals, np.clip(x0, lo + 1e-9, hi - 1e-9), bounds=(lo, hi),
                        x_scale="jac", max_nfev=80)
    return unpack(sol.x), float(sol.cost)


def fit_pendulum(recordings: list[Recording], lever_length: float = 0.25,
                 starts=((3.0, 0.5), (30.0, 3.0))) -> PendulumParams:
    """Least-squares pendulum parameters (handle_models.PendulumParams) over recordings: log
    rotational stiffness and damping per body axis, rest offset, lever (hinge -> centre) and
    log inertia per body axis; one solve per (stiffness, damping) start, the best kept. The
    Jacobian's finite differences run batched (simulate_pendulums)."""
    fits = [_fit_pendulum_from(recordings, lever_length, *s) for s in starts]
    return min(fits, key=lambda f: f[1])[0]


def _pendulum_unpack(x: np.ndarray) -> PendulumParams:
    return PendulumParams(np.exp(x[:3]), np.exp(x[3:6]), x[6:9], x[9:12], np.exp(x[12:15]))


def _pendulum_residuals(xs: np.ndarray, recordings: list[Recording]) -> np.ndarray:
    """Bag-centre residuals (B, 3 T_total) of B parameter vectors."""
    hs = [_pendulum_unpack(x) for x in xs]
    out = []
    for r in recordings:
        pos, _ = simulate_pendulums(hs, r.bag_mass, r.t, r.robot_position, r.robot_velocity,
                                    r.rotation, r.bag_position[0], r.bag_velocity[0])
        out.append((pos - r.bag_position).reshape(len(hs), -1))
    return np.concatenate(out, axis=1)


def _fit_pendulum_from(recordings: list[Recording], lever_length: float, k0: float,
                       c0: float) -> tuple[PendulumParams, float]:
    from scipy.optimize import least_squares

    d0 = np.mean([r.body_offsets().mean(axis=0) for r in recordings], axis=0)
    l0 = lever_length * d0 / np.linalg.norm(d0)
    x0 = np.concatenate([np.full(3, np.log(k0)), np.full(3, np.log(c0)), d0, l0,
                         np.full(3, np.log(0.25))])
    lo = np.concatenate([np.full(6, np.log(1e-3)), d0 - 0.1, l0 - 0.2, np.full(3, np.log(0.02))])
    hi = np.concatenate([np.full(3, np.log(1e4)), np.full(3, np.log(1e3)), d0 + 0.1, l0 + 0.2,
                         np.full(3, np.log(5.0))])

    def jac(x: np.ndarray) -> np.ndarray:
        h = 1e-6 * np.maximum(1.0, np.abs(x))
        steps = np.where(x + h > hi, -h, h)
        xs = np.vstack([x, x + np.diag(steps)])
        r = _pendulum_residuals(xs, recordings)
        return ((r[1:] - r[0]) / steps[:, None]).T

    sol = least_squares(lambda x: _pendulum_residuals(x[None], recordings)[0],
                        np.clip(x0, lo + 1e-9, hi - 1e-9), jac=jac, bounds=(lo, hi),
                        x_scale="jac", max_nfev=60)
    return _pendulum_unpack(sol.x), float(sol.cost)


def rigid_body(recordings: list[Recording]) -> RigidBodyParams:
    """The rigid-body model's one parameter: the mean body-frame bag offset of the recordings."""
    return RigidBodyParams(np.mean([r.body_offsets().mean(axis=0) for r in recordings], axis=0))


def horizon_error(handle, rec: Recording, flight_mode, horizon: float = 5.0,
                  every: float = 1.0) -> dict:
    """What the MPC relies on: from the recorded state every `every` s, roll the model out
    with the PD law on the recorded reference for `horizon` s (ReducedModel.rollout, rotation
    of the reference, the recorded robot attitude and rate at the start) and compare bag and
    robot centres with the recording (world frame, m): RMS over all windows and steps, max."""
    fp, fv, fa, fq = rec.reference
    ref_rot = np.array([rot.to_matrix(q) for q in fq])
    dt = float(np.median(np.diff(rec.t)))
    k = max(2, int(round(horizon / dt)))
    stride = max(1, int(round(every / dt)))
    gains = Gains.from_flight_mode(flight_mode)
    model = ReducedModel(handle)
    I_r = robot_mass().inertia
    eb, er = [], []
    for s in range(0, len(rec.t) - k - 1, stride):
        q = rec.robot_orientation[s]
        R = rot.to_matrix(q)
        w_b = np.zeros(3)
        if s > 0:   # body rate from the recorded attitudes
            w_b = rot.to_rotvec(rot.multiply(rot.conjugate(rec.robot_orientation[s - 1]), q)) / dt
        r_rel = R.T @ rot.to_matrix(rec.bag_orientation[s])
        start = RolloutStart(rec.robot_position[s], rec.robot_velocity[s], robot_mass().mass,
                             rec.ff_mass, rec.bag_position[s], rec.bag_velocity[s], rec.bag_mass,
                             rec.bag_size, None, r_rel, q, w_b, I_r, rec.ff_inertia)
        sr, sl = slice(s, s + k), slice(s + 1, s + 1 + k)   # reference at step i -> state i+1
        refs = CandidateReferences(fp[None, sr], fv[None, sr], fa[None, sr], ref_rot[sr], dt)
        out = model.rollout(start, refs, gains)
        eb.append(np.linalg.norm(out.bag_position[0] - rec.bag_position[sl], axis=1))
        er.append(np.linalg.norm(out.robot_position[0] - rec.robot_position[sl], axis=1))
    eb, er = np.concatenate(eb), np.concatenate(er)
    return {"bag_rms": float(np.sqrt(np.mean(eb ** 2))), "bag_max": float(eb.max()),
            "robot_rms": float(np.sqrt(np.mean(er ** 2)))}


# ---- the pair model with the swing (pair_model.PairParams) ------------------------------------
@dataclass
class PairRecording:
    """Truth states of a pushed flight sampled at every control tick, with the wrench applied
    over the following tick (body frame, boxed): what the pair model is fitted on."""

    t: np.ndarray
    x: np.ndarray          # (T, 26) pair_model states (bag frame: aligned with the robot at t[0])
    bag_position: np.ndarray
    wrench: np.ndarray     # (T, 6)


def pair_states(robot_position, robot_velocity, robot_q, robot_omega_world, bag_q, bag_omega_world,
                wrench) -> np.ndarray:
    """pair_model states (T, 26) from truth samples (T, ...); the bag frame is the bag's
    orientation turned so that it is the robot's at the first sample."""
    from . import pair_model as pm
    q_rel0 = rot.multiply(rot.conjugate(robot_q[0]), bag_q[0])        # bag in robot frame at t0
    qb = np.array([rot.normalize(rot.multiply(q, rot.conjugate(q_rel0))) for q in bag_q])
    wr = np.array([rot.rotate_inverse(q, w) for q, w in zip(robot_q, robot_omega_world)])
    wb = np.array([rot.rotate_inverse(q, w) for q, w in zip(qb, bag_omega_world)])
    return np.concatenate([robot_position, robot_velocity, robot_q, wr, qb, wb, wrench], 1) \
        if len(robot_q) else np.zeros((0, pm.NX))


def pair_windows(recs: list[PairRecording], horizon: float, every: float = 0.5) -> tuple:
    """Windows of `horizon` s starting every `every` s: start states (W, 26), wrenches
    (W, K, 6), the recorded robot and bag positions after each step (W, K, 3) x 2, and dt."""
    dt = float(np.median(np.diff(recs[0].t)))
    k = int(round(horizon / dt))
    stride = max(1, int(round(every / dt)))
    x0, us, pr, pb = [], [], [], []
    for r in recs:
        for s in range(0, len(r.t) - k - 1, stride):
            x0.append(r.x[s])
            us.append(r.wrench[s:s + k])
            pr.append(r.x[s + 1:s + 1 + k, 0:3])
            pb.append(r.bag_position[s + 1:s + 1 + k])
    return np.array(x0), np.array(us), np.array(pr), np.array(pb), dt


def pair_errors(params, windows, horizons=(1.0, 2.0, 5.0), substeps: int = 2) -> dict:
    """Open-loop prediction errors of the pair model under the recorded wrench: RMS over
    windows of the robot's and the bag centre's position error at each horizon (m)."""
    from . import pair_model as pm
    x0, us, pr, pb, dt = windows
    x0 = x0.copy()
    x0[:, pm.A] = us[:, 0]
    xs = pm.rollout(x0, us, dt, params, substeps=substeps)[:, 1:]
    bag, _ = pm.bag_centre(xs, params)
    out = {}
    for h in horizons:
        i = int(round(h / dt)) - 1
        if i < us.shape[1]:
            out[f"robot_{h:g}s"] = float(np.sqrt(np.mean(np.sum((xs[:, i, :3] - pr[:, i]) ** 2, -1))))
            out[f"bag_{h:g}s"] = float(np.sqrt(np.mean(np.sum((bag[:, i] - pb[:, i]) ** 2, -1))))
    return out


def fit_pair(base, windows, max_nfev: int = 20, substeps: int = 2, free_bag: bool = False,
             damping_max: float = 2.0):
    """Least squares of the pair model's joint (log stiffness, log damping per robot axis), the
    bag's drag and the grasp point on the robot on the windows' robot and bag position errors.
    The bag's grasp point follows from the mean rest offset, or (`free_bag`: swings large
    enough to pin the pendulum's length, as after a bump) is fitted too. `damping_max` (N m s/rad)
    bounds the joint's damping: its time constant must stay within the oracle's RK4 steps."""
    from scipy.optimize import least_squares

    from . import pair_model as pm
    if not damping_max > 1e-4:
        raise ValueError(f"damping_max must be > 1e-4 N m s/rad (the fit's lower bound), got {damping_max}")
    x0s, us, pr, pb, dt = windows
    rest = np.asarray(base.rest_offset())
    x0s = x0s.copy()
    x0s[:, pm.A] = us[:, 0]

    def unpack(z):
        g = z[7:10]
        return base.with_(stiffness=tuple(np.exp(z[0:3])), damping=tuple(np.exp(z[3:6])),
                          bag_drag=float(np.exp(z[6])), grasp_robot=tuple(g),
                          grasp_bag=tuple(z[10:13] if free_bag else g - rest))

    def res(z):
        p = unpack(z)
        xs = pm.rollout(x0s, us, dt, p, substeps=substeps)[:, 1:]
        bag, _ = pm.bag_centre(xs, p)
        return np.concatenate([(xs[..., :3] - pr).ravel(), (bag - pb).ravel()])

    z0 = np.concatenate([np.log(np.maximum(base.stiffness, 1e-3)),
                         np.log(np.maximum(base.damping, 1e-3)), [np.log(max(base.bag_drag, 1e-2))],
                         np.asarray(base.grasp_robot, float)])
    g0 = np.asarray(base.grasp_robot, float)
    lo = np.concatenate([np.full(7, np.log(1e-4)), g0 - 0.1])
    # bounds: a strap's twist, not a clamp (stiffer joints need smaller steps than the oracle's)
    hi = np.concatenate([np.full(3, np.log(5.0)), np.full(3, np.log(damping_max)), [np.log(20.0)], g0 + 0.1])
    if free_bag:                        # the bag's grasp point within 0.15 m of its start
        b0 = np.asarray(base.grasp_bag, float)
        z0, lo, hi = np.concatenate([z0, b0]), np.concatenate([lo, b0 - 0.15]), np.concatenate([hi, b0 + 0.15])
    sol = least_squares(res, np.clip(z0, lo + 1e-9, hi - 1e-9), bounds=(lo, hi), x_scale="jac",
                        max_nfev=max_nfev, diff_step=1e-3)
    return unpack(sol.x)
