"""The oracle's plan flown in the FEM simulator: does its answer hold on the real bag?

The flight (astrobee_lab.flight.Flight, in-process, truth state, the study's bump drawn from the
same seed) is flown by PD along the planned leg until the oracle's window opens; from then on
each tick commands the oracle's wrench for that interval (feed-forward) plus a PD feedback on
the robot around the oracle's planned state (the pair's mass, the pair's inertia about its
centre of mass, the flight mode's gains), boxed per axis. Judged as the verdict judges: over the
last `hold` s before the budget ends the robot is within the goal's tolerances and at rest
(|v| < 1 cm/s, |w| < 0.02 rad/s), and no contact happened.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from astrobee import rotations as rot
from astrobee_control import pair_model as pm

from .solve import REST_OMEGA, REST_SPEED, Leg, OracleResult


def _reference(res: OracleResult, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(position, velocity, quaternion, body rate, feed-forward wrench) of the plan at t."""
    k = int(np.clip(np.searchsorted(res.t, t, side="right") - 1, 0, len(res.u) - 1))
    s = float(np.clip((t - res.t[k]) / (res.t[k + 1] - res.t[k]), 0.0, 1.0))
    x = (1 - s) * res.x[k] + s * res.x[k + 1]
    q = x[pm.Q_R] / np.linalg.norm(x[pm.Q_R])
    return x[pm.P_R], x[pm.V_R], q, x[pm.W_R], res.u[k]


def fly(res: OracleResult, leg: Leg, params: pm.PairParams, seed: int, magnitude: float,
        nodes: int = 300, scenario: str = "node2_to_jem_bag", hold: float = 2.0,
        pair_inertia=(0.43, 1.51, 1.66)) -> dict[str, Any]:
    """Fly the oracle's plan `res` (see the module docstring); a row of what happened."""
    from astrobee_lab.flight import Flight
    realism = {"disturbances": [{"target": "bag", "magnitude": float(magnitude), "duration": 0.2,
                                 "t_min": 10.0, "t_max": 30.0}]} if magnitude > 0 else None
    t_end = float(res.t[-1])
    fl = Flight(scenario, seed=seed, controller="pd", bag_model="fem", bag_resolution=nodes,
                state_source="truth", realism=realism, task={"time_limit": t_end + 5.0})
    mode = fl.mode
    lim = np.concatenate([mode.max_force, mode.max_torque])
    M = params.robot_mass + params.bag_mass
    J = np.asarray(pair_inertia, float)
    kp, kd = np.asarray(mode.pos_kp, float), np.asarray(mode.vel_kd, float)
    akp, akd = np.asarray(mode.att_kp, float), np.asarray(mode.omega_kd, float)
    fl.reset()
    name = fl.names[0]
    contacts, clearance, tail = 0, np.inf, []
    while fl.sim.time < t_end - 1e-9:
        t = fl.sim.time
        if t < res.t[0]:
            _, sample = fl.step()
        else:
            p, q, v, w = fl._truth[name]
            q = rot.normalize(np.asarray(q, float))
            pr, vr, qr, wr, uff = _reference(res, t)
            f_w = M * (kp * (pr - p) + kd * (vr - v))
            e = rot.to_rotvec(rot.multiply(rot.conjugate(q), qr))
            w_b = rot.rotate_inverse(q, np.asarray(w, float))
            tau = J * (akp * e + akd * (wr - w_b))
            cmd = np.clip(uff + np.concatenate([rot.rotate_inverse(q, f_w), tau]), -lim, lim)
            _, sample = fl.step(cmd, mode="replace")
        contacts += int(sample.contacts)
        clearance = min(clearance, float(sample.bag_clearance))
        if fl.sim.time >= t_end - hold - 1e-9:
            p, q, v, w = fl._truth[name]
            tail.append((np.linalg.norm(np.asarray(p) - leg.goal_position),
                         rot.angle_between(rot.normalize(np.asarray(q, float)), leg.goal_orientation),
                         np.linalg.norm(v), np.linalg.norm(w)))
    log = getattr(fl.sim, "disturbance_log", [])
    log = log() if callable(log) else log
    fl.close()
    tail = np.array(tail)
    goal, att, speed, omega = tail.max(axis=0)
    ok = bool(goal <= mode.tolerance_pos and att <= mode.tolerance_att and speed < REST_SPEED
              and omega < REST_OMEGA and contacts == 0)
    return {"flown_success": ok, "flown_goal": round(float(goal), 4), "flown_attitude": round(float(att), 4),
            "flown_speed": round(float(speed), 4), "flown_omega": round(float(omega), 4),
            "flown_contacts": contacts, "flown_min_bag_clearance": round(float(clearance), 4),
            "bump_seen": log[0]["force"] if log else None}
