"""The FEM bag's cost per grasp model (astrobee_sim.grasp): strap (the default) vs hinge vs clamp.

Library real-time factor of the fast FEM bag (~400 nodes) while a PD law drags it (sim_rtf.py's
library loop: physics 350 Hz, one command per 16 ms tick, bag state + clearance + contacts every
tick), by the wall clock and per CPU second, rounds interleaved (medians); then batched
rollouts (K=64 copies, fem_rollout) per grasp in bag-seconds per CPU second; then the three
bags side by side in one process, 0.5 s chunks in turn (CPU us per physics step: the fairest
A/B on a shared machine). References: the clamp in the same run, and docs/benchmarks.md's
fast solver at 412 nodes (fem_fast_bench.py: 9.6x per CPU s quiet; ~5.7x per CPU s in a
loaded run).

    .venv/bin/python bench/grasp_bench.py [--rounds 3] [--seconds 2] [--chunks 12]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from sim_rtf import drag_rtf, goal_at, pd_wrench

GRASPS = ("strap", "hinge", "clamp")
REF_CPU = "9.6x per CPU s (fem_fast_bench, quiet); ~5.7x in a loaded run"


def library(grasp: str, res: int, seconds: float) -> tuple[float, float, int]:
    """(wall, CPU) real-time factor of the library loop with the fast FEM bag held by `grasp`."""
    from astrobee_sim.simulation import Simulation
    sim = Simulation("node2_to_jem_bag", bag_model="fem", bag_resolution=res, fem_solver="fast",
                     grasp=grasp)
    try:
        return (*drag_rtf(sim, seconds), sim.bag.num_nodes)
    finally:
        sim.close()


def batched(grasp: str, res: int, k: int, seconds: float) -> float:
    """Bag-seconds per CPU second of K rollout copies held by `grasp` (open space)."""
    from astrobee_sim.bags.fem_rollout import FemRollout
    from astrobee_sim.simulation import Simulation
    sim = Simulation("node2_to_jem_bag", bag_model="fem", bag_resolution=res, fem_solver="fast",
                     grasp=grasp)
    try:
        rng = np.random.default_rng(0)
        wr = np.c_[rng.uniform(-0.5, 0.5, (k, 3)), rng.uniform(-0.05, 0.05, (k, 3))]
        ro = FemRollout.from_bag(sim.bag, sim.robots[""], k, sim.dt)
        ro.step(wr, 1)
        steps = max(1, int(round(seconds / sim.dt)))
        c0 = time.process_time()
        ro.step(wr, steps)
        return k * steps * sim.dt / max(time.process_time() - c0, 1e-9)
    finally:
        sim.close()


def same_process(res: int, chunks: int) -> dict:
    """CPU us per physics step of each grasp's bag, dragged in 0.5 s chunks in turn in one
    process (the same drag as drag_rtf): {grasp: [per chunk]}."""
    from astrobee_sim.simulation import Simulation
    sims = {g: Simulation("node2_to_jem_bag", bag_model="fem", bag_resolution=res,
                          fem_solver="fast", grasp=g) for g in GRASPS}
    start = {g: s.robot_state()[:2] for g, s in sims.items()}

    def drag(g: str, seconds: float) -> int:
        s, (p0, q0) = sims[g], start[g]
        end, n0 = s.time + seconds, s.steps
        while s.time < end - 1e-9:
            pos, q, v, w = s.robot_state()
            s.command(pd_wrench(pos, q, v, w, goal_at(s.time, p0), q0))
            s.step(6)
            s.bag_state()
            s.clearance()
            s.contacts()
        return s.steps - n0
    try:
        for g in GRASPS:
            drag(g, 0.3)
        out: dict = {g: [] for g in GRASPS}
        for _ in range(chunks):
            for g in GRASPS:
                c0 = time.process_time()
                n = drag(g, 0.5)
                out[g].append((time.process_time() - c0) / n * 1e6)
        return out
    finally:
        for s in sims.values():
            s.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--resolution", type=int, default=400)
    ap.add_argument("--chunks", type=int, default=12)
    a = ap.parse_args()
    lib: dict = {g: ([], []) for g in GRASPS}
    bat: dict = {g: [] for g in GRASPS}
    nodes = 0
    for _ in range(a.rounds):
        for g in GRASPS:
            wall, cpu, nodes = library(g, a.resolution, a.seconds)
            lib[g][0].append(wall)
            lib[g][1].append(cpu)
            bat[g].append(batched(g, a.resolution, 64, 0.1))
    print(f"\nfast FEM bag, {nodes} nodes, PD dragging it; medians of {a.rounds} interleaved "
          f"rounds; reference: {REF_CPU}")
    print(f"{'grasp':<8}{'wall RTF':>10}{'CPU RTF':>10}{'vs clamp':>10}{'K=64 bag-s/CPU s':>19}")
    ref = float(np.median(lib["clamp"][1]))
    for g in GRASPS:
        cpu = float(np.median(lib[g][1]))
        print(f"{g:<8}{np.median(lib[g][0]):>9.1f}x{cpu:>9.1f}x{cpu / ref:>9.2f}x"
              f"{np.median(bat[g]):>19.1f}")
    one = same_process(a.resolution, a.chunks)
    print(f"\nthe three in one process, {a.chunks} chunks of 0.5 s in turn: CPU us per physics "
          f"step (median, quartiles)")
    ref = float(np.median(one["clamp"]))
    for g in GRASPS:
        q1, m, q3 = np.percentile(one[g], [25, 50, 75])
        print(f"{g:<8}{m:>8.0f} us ({q1:.0f}-{q3:.0f})  vs clamp {m / ref:.3f}x")


if __name__ == "__main__":
    main()
