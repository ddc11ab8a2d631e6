"""Bench: RMS position tracking error of the PD tracker flying Node 2 -> JEM in the pybullet
simulation (no transport), without a bag and carrying the rigid bag (with and without telling
the controller about the bag's mass). Prints one table.

    .venv/bin/python bench/control_tracking.py [--quick | --full]
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from astrobee import config, flight_modes
from astrobee import rotations as rot
from astrobee_control import mass as mp
from astrobee_control.pd import PdTracker, State
from astrobee_control.reference import SampledTrajectory, rest_to_rest

CONTROL_RATE = 62.5


def reference(scenario: dict, mode) -> tuple[SampledTrajectory, str]:
    """The planner library's trajectory when it is available, else a min-jerk straight line."""
    start = np.asarray(scenario["robots"][0]["position"], float)
    q0 = np.asarray(scenario["robots"][0]["orientation"], float)
    goal = np.asarray(scenario["goal"]["position"], float)
    q1 = np.asarray(scenario["goal"]["orientation"], float)
    try:
        from astrobee_planning.position_planner import plan_position
        plan = plan_position(start, goal, mode.hard_limit_vel, mode.hard_limit_accel)
        sp = plan.spline
        t = np.arange(0.0, sp.duration, 0.1)
        t = np.append(t, sp.duration)
        quats = np.array([rot.slerp(q0, q1, s) for s in t / sp.duration])
        z = np.zeros((len(t), 3))
        return SampledTrajectory(t, sp.evaluate(t, 0), sp.evaluate(t, 1), sp.evaluate(t, 2),
                                 quats, z, z), "global planner"
    except Exception as exc:  # noqa: BLE001 - planner not there yet / API changed
        dist = float(np.linalg.norm(goal - start))
        dur = max(1.875 * dist / mode.hard_limit_vel, np.sqrt(5.77 * dist / mode.hard_limit_accel))
        return rest_to_rest(start, goal, q0, q1, dur), f"min-jerk line ({type(exc).__name__})"


def fly(scenario_name: str, informed: bool, settle: float) -> dict:
    from astrobee_sim.simulation import Simulation

    scen = config.scenario(scenario_name)
    mode = flight_modes.get(scen.get("flight_mode"))
    traj, source = reference(scen, mode)
    sim = Simulation(scenario_name)
    robot = mp.robot()
    tracker = PdTracker(mode, robot)
    bag = scen.get("bag") or {}
    errs, t, wall0 = [], 0.0, time.perf_counter()
    steps_done = 0
    while t < traj.duration + settle:
        pos, q, v, w = sim.robot_state()
        state = State(pos, v, q, rot.rotate_inverse(q, w))
        if informed and sim.bag is not None:
            b = sim.bag_state()
            off = rot.rotate_inverse(q, b.position - pos)
            r_rel = rot.to_matrix(q).T @ rot.to_matrix(b.orientation)
            tracker.set_mass(mp.with_bag(robot, float(bag.get("mass", 10.0)),
                                         bag.get("size", [0.5, 0.42, 0.25]), off, r_rel))
        ref = traj.sample(t)
        out = tracker.step(state, ref, 1.0 / CONTROL_RATE)
        if t <= traj.duration:
            errs.append(float(np.linalg.norm(ref.position - pos)))
        sim.command(np.concatenate([out.force, out.torque]))
        t += 1.0 / CONTROL_RATE
        target = int(round(t / sim.dt))
        sim.step(target - steps_done)
        steps_done = target
    pos, q, _, _ = sim.robot_state()
    goal = np.asarray(scen["goal"]["position"], float)
    contacts = len(sim.contacts())
    e = np.asarray(errs)
    return {"case": scenario_name + ("" if not bag else (" informed" if informed else " naive")),
            "rms": float(np.sqrt(np.mean(e**2))), "max": float(e.max()),
            "final": float(np.linalg.norm(pos - goal)),
            "final_att": rot.angle_between(q, np.asarray(scen["goal"]["orientation"], float)),
            "duration": traj.duration, "source": source, "contacts": contacts,
            "wall": time.perf_counter() - wall0}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="(default) the Node 2 -> JEM trip")
    p.add_argument("--full", action="store_true", help="also a longer settle after the end")
    a = p.parse_args(argv)
    settle = 15.0 if a.full else 5.0
    rows = [fly("node2_to_jem", True, settle), fly("node2_to_jem_bag", True, settle),
            fly("node2_to_jem_bag", False, settle)]
    base = rows[0]["rms"]
    print("PD tracking, Node 2 -> JEM, nominal flight mode (pybullet, 350 Hz physics, 62.5 Hz control)")
    print(f"reference: {rows[0]['source']}, {rows[0]['duration']:.1f} s")
    hdr = f"{'case':<28}{'RMS err (m)':>12}{'max err (m)':>12}{'final (m)':>11}{'final (rad)':>12}" \
          f"{'vs no bag':>10}{'contacts':>9}{'wall (s)':>9}"
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        print(f"{r['case']:<28}{r['rms']:>12.4f}{r['max']:>12.4f}{r['final']:>11.4f}"
              f"{r['final_att']:>12.4f}{r['rms'] / base:>9.1f}x{r['contacts']:>9d}{r['wall']:>9.1f}")
    print("reference figure: pyastrobee reports no RMS figure for its PD; nominal tolerance 0.2 m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
