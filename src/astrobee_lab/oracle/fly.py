"""The oracle's plan flown in the FEM simulator: does its answer hold on the real bag?

The flight (astrobee_lab.flight.Flight, in-process, truth state, the study's bump drawn from the
same seed) is flown by PD along the planned leg until the oracle's window opens; from then on
each tick commands the oracle's wrench for that tick (feed-forward) plus feedback, boxed per
axis: `lqr` (default) a time-varying LQR on the pair model linearised along the oracle's
solution, fed the robot's truth state and the FEM bag's fitted orientation and rate
(tracking.py); `pd` the earlier PD on the robot alone around the planned robot state (pair mass,
pair inertia, the mode's gains). Judged as the verdict judges: over the last `hold` s before the
budget ends the robot is within the goal's tolerances and at rest (|v| < 1 cm/s, |w| < 0.02
rad/s), and no contact happened. trace=True also returns, per tick, what the flight did against
what the oracle predicted (robot and bag errors, the FEM nodes' and the predicted corners' wall
clearance).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from astrobee import rotations as rot
from astrobee_control import pair_model as pm

from . import tracking
from .solve import REST_OMEGA, REST_SPEED, Leg, OracleResult, bag_corners, solve


def _reference(res: OracleResult, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(position, velocity, quaternion, body rate, feed-forward wrench) of the plan at t."""
    k = int(np.clip(np.searchsorted(res.t, t, side="right") - 1, 0, len(res.u) - 1))
    s = float(np.clip((t - res.t[k]) / (res.t[k + 1] - res.t[k]), 0.0, 1.0))
    x = (1 - s) * res.x[k] + s * res.x[k + 1]
    q = x[pm.Q_R] / np.linalg.norm(x[pm.Q_R])
    return x[pm.P_R], x[pm.V_R], q, x[pm.W_R], res.u[k]


def measured_state(truth: tuple, bag: Any, bag_offset: np.ndarray) -> np.ndarray:
    """The pair state (26,) of the flight: the robot's truth, the FEM bag's fitted orientation
    (times the start's robot-to-bag offset, so aligned at rest as the model) and body rate."""
    p, q, v, w = truth
    q = rot.normalize(np.asarray(q, float))
    qb = rot.normalize(rot.multiply(rot.normalize(np.asarray(bag.orientation, float)), bag_offset))
    wb = rot.rotate_inverse(qb, np.asarray(bag.omega, float))
    return pm.state(np.asarray(p, float), np.asarray(v, float), q,
                    rot.rotate_inverse(q, np.asarray(w, float)), qb, wb)


def fly(res: OracleResult, leg: Leg, params: pm.PairParams, seed: int, magnitude: float,
        nodes: int = 300, scenario: str = "node2_to_jem_bag", hold: float = 2.0,
        feedback: str = "lqr", pair_inertia=(0.43, 1.51, 1.66), scale: dict | None = None,
        trace: bool = False, replan: float = 0.0, solve_kw: dict | None = None,
        react: float | None = None) -> dict[str, Any]:
    """Fly the oracle's plan `res` (see the module docstring); a row of what happened (and
    the per-tick trace under "trace" when asked). replan > 0 (lqr only): every `replan` s of
    simulated time the oracle is solved again from the measured pair state (the last plan as
    the guess; the simulation waits for the solver: an idealised replanning MPC) until
    `hold` + 5 s before the budget ends, and the LQR re-linearised along the new plan; solve_kw:
    keywords of the solves made in flight (margin, bag_margin: as the first plan's). react (s,
    lqr only): the bump is not foreknown: PD flies until `react` s after the bump's end (as a
    detector on the bag's state would see it), then the oracle is solved from the measured pair
    state without a bump (the simulation waits for it, as for a replan); `res` then only gives
    the window's end."""
    from astrobee_lab.flight import Flight
    if feedback not in ("lqr", "pd"):
        raise ValueError(f"feedback must be lqr or pd, got {feedback!r}")
    if (react is not None or replan > 0) and feedback != "lqr":
        raise ValueError("react and replan need the lqr feedback")
    realism = {"disturbances": [{"target": "bag", "magnitude": float(magnitude), "duration": 0.2,
                                 "t_min": 10.0, "t_max": 30.0}]} if magnitude > 0 else None
    t_end = float(res.t[-1])
    fl = Flight(scenario, seed=seed, controller="pd", bag_model="fem", bag_resolution=nodes,
                state_source="truth", realism=realism, task={"time_limit": t_end + 5.0})
    mode = fl.mode
    lim = np.concatenate([mode.max_force, mode.max_torque])
    fl.reset()
    name = fl.names[0]
    # the FEM bag's fitted frame against the robot's at the start (the model's rest: aligned)
    q0 = rot.normalize(np.asarray(fl._truth[name][1], float))
    bag_offset = rot.multiply(rot.conjugate(rot.normalize(np.asarray(fl._bag.orientation, float))), q0)
    # with react the LQR waits for the plan solved after the bump (the foreknown one is not flown)
    track = tracking.plan(res, params, lim, 1.0 / 62.5, scale) \
        if feedback == "lqr" and react is None else None
    M = params.robot_mass + params.bag_mass
    J = np.asarray(pair_inertia, float)
    kp, kd = np.asarray(mode.pos_kp, float), np.asarray(mode.vel_kd, float)
    akp, akd = np.asarray(mode.att_kp, float), np.asarray(mode.omega_kd, float)
    corners = bag_corners(leg.bag_size)
    world = fl.sim.world
    contacts, clearance, tail, rows, replans = 0, np.inf, [], [], []
    start = float(res.t[0])
    reacted: dict = {}                   # the solve made after the bump (react)
    if react is not None:
        (pulse,) = fl.sim.disturbance_schedule()
        start = float(pulse["time"]) + float(pulse["duration"]) + float(react)
    solve_kw = dict(solve_kw or {})
    next_replan = start + replan
    while fl.sim.time < t_end - 1e-9:
        t = fl.sim.time
        if t < start:
            _, sample = fl.step()
        else:
            x = measured_state(fl._truth[name], fl._bag, bag_offset)
            if track is None and react is not None:
                res = solve(leg, params, None, t0=t, x0=x, **solve_kw)
                reacted = {"react_at": round(t, 2), "react_feasible": res.feasible,
                           "react_solve_time": round(res.solve_time, 1)}
                track = tracking.plan(res, params, lim, 1.0 / 62.5, scale)
            if track is not None and replan > 0 and next_replan <= t < t_end - hold - 5.0:
                b = res.bump if res.bump is not None and res.bump.time > t else None
                res = solve(leg, params, b, t0=t, x0=x, guess=res, **solve_kw)
                replans.append((round(t, 2), res.feasible, round(res.solve_time, 1)))
                track = tracking.plan(res, params, lim, 1.0 / 62.5, scale)
                next_replan = t + replan
            if track is not None:
                cmd = track.command(x, t, lim)
            else:
                p, q, v, w_b = x[pm.P_R], x[pm.Q_R], x[pm.V_R], x[pm.W_R]
                pr, vr, qr, wr, uff = _reference(res, t)
                f_w = M * (kp * (pr - p) + kd * (vr - v))
                e = rot.to_rotvec(rot.multiply(rot.conjugate(q), qr))
                tau = J * (akp * e + akd * (wr - w_b))
                cmd = np.clip(uff + np.concatenate([rot.rotate_inverse(q, f_w), tau]), -lim, lim)
            _, sample = fl.step(cmd, mode="replace")
            if trace:
                rows.append({**_trace_row(fl, name, res, track, params, corners, world, bag_offset),
                             "cmd": cmd})
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
    out = {"feedback": feedback, "flown_success": ok, "flown_goal": round(float(goal), 4),
           "flown_attitude": round(float(att), 4), "flown_speed": round(float(speed), 4),
           "flown_omega": round(float(omega), 4), "flown_contacts": contacts,
           "flown_min_bag_clearance": round(float(clearance), 4),
           "bump_seen": log[0]["force"] if log else None,
           "replans": len(replans), "replans_feasible": sum(f for _, f, _ in replans),
           **reacted}
    if trace:
        out["trace"] = {k: np.array([r[k] for r in rows]) for k in rows[0]} if rows else {}
    return out


def _trace_row(fl: Any, name: str, res: OracleResult, track: Any, params: pm.PairParams,
               corners: np.ndarray, world: Any, bag_offset: np.ndarray) -> dict:
    """One tick: the flight against the oracle's prediction at the same time."""
    t = fl.sim.time
    x = measured_state(fl._truth[name], fl._bag, bag_offset)
    if track is not None:
        ref = track.x[track.index(t)]
    else:
        k = int(np.clip(np.searchsorted(res.t, t, side="right") - 1, 0, len(res.x) - 1))
        ref = res.x[k]
    e = tracking.error(x[None], ref[None], False)[0]
    pb_ref, _ = pm.bag_centre(ref, params)
    pb_mod, _ = pm.bag_centre(x, params)         # where the model puts the bag for this state
    pts = fl.sim.bag_points()
    centre = np.asarray(fl._bag.position, float)         # the mesh frame's origin: the box centre
    Rb = pm.rotation(ref[pm.Q_B])
    pred = pb_ref + corners @ Rb.T
    return {"t": t, "pos_err": float(np.linalg.norm(e[0:3])), "att_err": float(np.linalg.norm(e[6:9])),
            "bag_att_err": float(np.linalg.norm(e[12:15])),
            "bag_centre_err": float(np.linalg.norm(centre - pb_ref)),
            "bag_model_err": float(np.linalg.norm(centre - pb_mod)),
            "swing": float(rot.angle_between(x[pm.Q_R], x[pm.Q_B])),
            "swing_ref": float(rot.angle_between(ref[pm.Q_R], ref[pm.Q_B])),
            "node_clearance": float(world.clearance(pts)),
            "corner_clearance_ref": float(world.clearance(pred)),
            "deform": float(fl._bag.deformation), "x": x}
