"""Where an FEM bag step goes, by pybullet's own profiler (why 3x real time at ~400 nodes is out
of reach on stock pybullet 3.2.7).

The Simulation drags a ~400-node bag back and forth with the PD law of bench/sim_rtf.py; after a
warm-up, pybullet's STATE_LOGGING_PROFILE_TIMINGS records one simulated second and the scopes are
summed per physics step. The deformable world integrates the mass-spring damping implicitly:
every step runs a conjugate-residual solve (btConjugateResidual, absolute tolerance 1e-8, up to
300 iterations, none of it exposed by pybullet) whose each iteration is one `multiply` over every
spring. 3x real time at 350 Hz leaves 952 us for the whole step.

    .venv/bin/python bench/sim_fem_profile.py [--resolution 400]
"""
from __future__ import annotations

import argparse
import collections
import json
import os
import re
import tempfile
import time

import pybullet as p

from astrobee_sim.simulation import Simulation
from sim_rtf import goal_at, pd_wrench

SCOPES = [("internalSingleStepSimulation", "whole physics step"),
          ("CRSolve", "implicit damping solve (conjugate residual)"),
          ("multiply", "  of which matrix products (one per iteration)"),
          ("predictUnconstraintMotion", "explicit spring forces + motion prediction"),
          ("computeResidual", "residual"),
          ("btDeformableMultiBodyDynamicsWorld::performGeometricCollisions", "soft-body collisions")]


def drive(sim: Simulation, until: float, start, q0) -> None:
    tick = int(round(sim.time / 0.016))
    while sim.time < until:
        pos, q, v, w = sim.robot_state()
        sim.command(pd_wrench(pos, q, v, w, goal_at(sim.time, start), q0))
        tick += 1
        sim.step(max(1, int(round(tick * 0.016 / sim.dt)) - sim.steps))


def scopes(path: str) -> tuple[dict, dict]:
    """Total microseconds and call counts per profiler scope name."""
    events = json.load(open(path))["traceEvents"]
    stack, tot, cnt = [], collections.Counter(), collections.Counter()
    for e in events:
        name = re.sub(r"\d+$", "", e["name"])
        if e["ph"] == "B":
            stack.append((name, e["ts"]))
        elif e["ph"] == "E" and stack:
            n, ts = stack.pop()
            tot[n] += e["ts"] - ts
            cnt[n] += 1
    return tot, cnt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=400)
    a = ap.parse_args()
    sim = Simulation("node2_to_jem_bag", bag_model="fem", bag_resolution=a.resolution,
                     fem_solver="bullet")       # pybullet's profiler: Bullet's soft body
    try:
        start, q0 = sim.robot_state()[:2]
        springs = len({tuple(sorted(e)) for t in sim.bag.mesh.tets.tolist()
                       for e in ((t[0], t[1]), (t[0], t[2]), (t[0], t[3]), (t[1], t[2]),
                                 (t[1], t[3]), (t[2], t[3]))})
        drive(sim, 2.0, start, q0)
        fd, path = tempfile.mkstemp(suffix=".json", prefix="femprof_")
        os.close(fd)
        steps0 = sim.steps
        log = p.startStateLogging(p.STATE_LOGGING_PROFILE_TIMINGS, path, physicsClientId=sim.client)
        t0 = time.perf_counter()
        drive(sim, 3.0, start, q0)
        wall = time.perf_counter() - t0
        p.stopStateLogging(log, physicsClientId=sim.client)
        n = sim.steps - steps0
        nodes = len(sim.bag.mesh.nodes)
        files = [f for f in os.listdir(os.path.dirname(path)) if f.startswith(os.path.basename(path))]
        tot, cnt = scopes(os.path.join(os.path.dirname(path), sorted(files)[-1]))
        for f in files:
            os.unlink(os.path.join(os.path.dirname(path), f))
        if os.path.exists(path):
            os.unlink(path)
    finally:
        sim.close()
    print(f"\nFEM bag step by pybullet's profiler ({nodes} nodes, {springs} springs, dragged by the "
          f"PD law; {n} steps)")
    print(f"{'scope':<50}{'us/step':>9}{'calls/step':>12}")
    for key, label in SCOPES:
        print(f"{label:<50}{tot[key] / n:>9.0f}{cnt[key] / n:>12.1f}")
    per = wall / n * 1e6
    print(f"{'loop wall time per step (profiling on)':<50}{per:>9.0f}")
    print(f"{'3x real time needs at most':<50}{1e6 / 350 / 3:>9.0f}")
    print("reference: pyastrobee 0.6x real time at 379 nodes (FACTS.md section 6)")


if __name__ == "__main__":
    main()
