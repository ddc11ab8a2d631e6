"""Rollout model B (the paper's way, for comparison): pybullet rollouts of a reduced bag.

A small pool of worker processes, each with its own pybullet DIRECT client (pybullet holds the
GIL while stepping and clients cannot be pickled, FACTS.md 5), each holding a robot box and a
rigid bag box. Per decision the caller's candidates are split over the workers; a worker places
robot and bag at the start state, ties the bag to the robot (`constraint`: five soft
point-to-point constraints of 2.5 N at the handle face, as the simulator's constraint bag;
`rigid`: one ball joint), saves that state once and, per candidate, restores it
(saveState/restoreState: the snapshot/restore the paper patched Bullet for) and steps the PD
law's force at `physics_rate`. As in model A, the robot's attitude is set to the reference's
each step and the bag is the only free rotation.

This module imports pybullet itself and builds its own bodies: control never imports the
simulator package.
"""
from __future__ import annotations

import multiprocessing as mpr

import numpy as np

from .reduced_model import CandidateReferences, Gains, Rollouts, RolloutStart

BAG_MODELS = ("constraint", "rigid")
_W: dict = {}   # the worker process's pybullet world


def _quat_from_matrix(R: np.ndarray) -> list[float]:
    from scipy.spatial.transform import Rotation
    return Rotation.from_matrix(R).as_quat().tolist()


def _init_worker(robot_size: float) -> None:
    import pybullet as p
    c = p.connect(p.DIRECT)
    p.setGravity(0, 0, 0, physicsClientId=c)
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=[robot_size / 2] * 3, physicsClientId=c)
    robot = p.createMultiBody(9.58, col, -1, [0, 0, 0], physicsClientId=c)
    p.changeDynamics(robot, -1, linearDamping=0, angularDamping=0, physicsClientId=c,
                     activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING)
    _W.update(p=p, c=c, robot=robot, bag=None, bag_key=None, constraints=[])


def _bag_body(size: np.ndarray, mass: float) -> int:
    p, c = _W["p"], _W["c"]
    key = (tuple(np.round(size, 4)), round(mass, 4))
    if _W["bag_key"] != key:
        if _W["bag"] is not None:
            p.removeBody(_W["bag"], physicsClientId=c)
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=(size / 2).tolist(), physicsClientId=c)
        b = p.createMultiBody(mass, col, -1, [0, 0, 0], physicsClientId=c)
        p.changeDynamics(b, -1, linearDamping=0, angularDamping=0, physicsClientId=c,
                         activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING)
        p.setCollisionFilterPair(_W["robot"], b, -1, -1, 0, physicsClientId=c)
        _W["bag"], _W["bag_key"] = b, key
    return _W["bag"]


def _rollout_chunk(args) -> tuple:
    (bag_model, rate, start, pos, vel, acc, rotation, dt, kp, kd, fmax) = args
    p, c, robot = _W["p"], _W["c"], _W["robot"]
    n, m = pos.shape[:2]
    sub = max(1, int(round(dt * rate)))
    p.setTimeStep(dt / sub, physicsClientId=c)
    p.changeDynamics(robot, -1, mass=float(start.robot_mass), physicsClientId=c)
    for cid in _W["constraints"]:
        p.removeConstraint(cid, physicsClientId=c)
    _W["constraints"] = []
    quats = [_quat_from_matrix(R) for R in rotation]
    x0 = np.asarray(start.robot_position, float)
    p.resetBasePositionAndOrientation(robot, x0.tolist(), quats[0], physicsClientId=c)
    p.resetBaseVelocity(robot, list(map(float, start.robot_velocity)), [0, 0, 0], physicsClientId=c)
    carrying = start.carrying
    if carrying:
        bag = _bag_body(np.asarray(start.bag_size, float), float(start.bag_mass))
        R0 = rotation[0]
        q_bag = _quat_from_matrix(R0 @ start.bag_rotation)
        xb = np.asarray(start.bag_position, float)
        p.resetBasePositionAndOrientation(bag, xb.tolist(), q_bag, physicsClientId=c)
        p.resetBaseVelocity(bag, list(map(float, start.bag_velocity)), [0, 0, 0], physicsClientId=c)
        # handle: the point of the bag's surface on the line to the robot centre
        u = x0 - xb
        dist = float(np.linalg.norm(u))
        half = np.asarray(start.bag_size, float) / 2
        ub = (R0 @ start.bag_rotation).T @ (u / max(dist, 1e-9))
        s = float(np.min(half / np.maximum(np.abs(ub), 1e-9)))
        handle_w = xb + (R0 @ start.bag_rotation) @ (ub * s)
        offsets = [np.zeros(3)]
        if bag_model == "constraint":
            t1 = np.cross(u, [0, 0, 1.0]) if abs(u[2]) < 0.9 * dist else np.cross(u, [1.0, 0, 0])
            t1 /= np.linalg.norm(t1)
            t2 = np.cross(u / max(dist, 1e-9), t1)
            offsets += [t1 * 0.05, -t1 * 0.05, t2 * 0.05, -t2 * 0.05]
        q_bag_inv = p.invertTransform([0, 0, 0], q_bag)[1]
        q_rob_inv = p.invertTransform([0, 0, 0], quats[0])[1]
        for off in offsets:
            w = handle_w + off
            in_robot = p.multiplyTransforms([0, 0, 0], q_rob_inv, (w - x0).tolist(), [0, 0, 0, 1])[0]
            in_bag = p.multiplyTransforms([0, 0, 0], q_bag_inv, (w - xb).tolist(), [0, 0, 0, 1])[0]
            cid = p.createConstraint(robot, -1, bag, -1, p.JOINT_POINT2POINT, [0, 0, 0], in_robot,
                                     in_bag, physicsClientId=c)
            p.changeConstraint(cid, maxForce=2.5 if bag_model == "constraint" else 500.0,
                               physicsClientId=c)
            _W["constraints"].append(cid)
    snap = p.saveState(physicsClientId=c)
    out_xr, out_vr, out_f = np.empty((n, m, 3)), np.empty((n, m, 3)), np.empty((n, m, 3))
    out_xb, out_vb = np.empty((n, m, 3)), np.empty((n, m, 3))
    ff = float(start.ff_mass)
    for j in range(n):
        p.restoreState(stateId=snap, physicsClientId=c)
        xr, vr = x0.copy(), np.asarray(start.robot_velocity, float).copy()
        for i in range(m):
            R = rotation[i]
            a_w = acc[j, i] + kp * (pos[j, i] - xr) + kd * (vel[j, i] - vr)
            F = R @ np.clip(ff * (R.T @ a_w), -fmax, fmax)
            out_f[j, i] = F
            for _ in range(sub):
                p.resetBasePositionAndOrientation(robot, xr.tolist(), quats[i], physicsClientId=c)
                p.resetBaseVelocity(robot, vr.tolist(), [0, 0, 0], physicsClientId=c)
                p.applyExternalForce(robot, -1, F.tolist(), xr.tolist(), p.WORLD_FRAME,
                                     physicsClientId=c)
                p.stepSimulation(physicsClientId=c)
                xr_t, _ = p.getBasePositionAndOrientation(robot, physicsClientId=c)
                vr_t, _ = p.getBaseVelocity(robot, physicsClientId=c)
                xr, vr = np.array(xr_t), np.array(vr_t)
            out_xr[j, i], out_vr[j, i] = xr, vr
            if carrying:
                out_xb[j, i] = p.getBasePositionAndOrientation(_W["bag"], physicsClientId=c)[0]
                out_vb[j, i] = p.getBaseVelocity(_W["bag"], physicsClientId=c)[0]
    p.removeState(snap, physicsClientId=c)
    return out_xr, out_vr, (out_xb if carrying else None), (out_vb if carrying else None), out_f


class PybulletModel:
    """Rollout model B: the same RolloutModel interface over worker processes."""

    name = "pybullet"

    def __init__(self, workers: int = 2, bag_model: str = "constraint",
                 physics_rate: float = 125.0, robot_size: float = 0.32) -> None:
        if bag_model not in BAG_MODELS:
            raise ValueError(f"pybullet rollout bag model must be one of {', '.join(BAG_MODELS)}, "
                             f"got {bag_model!r}")
        if int(workers) != workers or workers <= 0:
            raise ValueError(f"workers must be a positive integer, got {workers!r}")
        if not physics_rate > 0:
            raise ValueError(f"physics_rate must be > 0, got {physics_rate!r}")
        self.bag_model, self.physics_rate, self.workers = bag_model, float(physics_rate), int(workers)
        ctx = mpr.get_context("spawn")
        self.pool = ctx.Pool(self.workers, initializer=_init_worker, initargs=(robot_size,))

    def rollout(self, start: RolloutStart, refs: CandidateReferences, gains: Gains) -> Rollouts:
        n = refs.position.shape[0]
        parts = [s for s in np.array_split(np.arange(n), self.workers) if len(s)]
        kp, kd = np.asarray(gains.kp, float), np.asarray(gains.kd, float)
        jobs = [(self.bag_model, self.physics_rate, start, refs.position[s], refs.velocity[s],
                 refs.accel[s], refs.rotation, refs.dt, kp, kd, np.asarray(gains.max_force, float))
                for s in parts]
        res = self.pool.map(_rollout_chunk, jobs)
        cat = lambda k: None if res[0][k] is None else np.concatenate([r[k] for r in res])  # noqa: E731
        return Rollouts(cat(0), cat(1), cat(2), cat(3), cat(4))

    def close(self) -> None:
        self.pool.terminate()
        self.pool.join()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:   # interpreter shutting down
            pass
