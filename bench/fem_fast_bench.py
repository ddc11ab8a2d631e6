"""Fast FEM solver vs Bullet's soft body: library real-time factor while a PD law drags the bag,
and batched rollouts (K copies of robot + bag in one step call), in bag-seconds per wall second.

Same loop as bench/sim_rtf.py's library column (physics at 350 Hz, one PD command per 16 ms
tick, bag state + clearance + contacts read every tick), both solvers in the same run.
Targets (issue 12): ~400 nodes >= 3x real time (goal 10x), ~1500 nodes >= 1x.

    .venv/bin/python bench/fem_fast_bench.py [--full]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from astrobee_sim.bags.fem_rollout import FemRollout
from astrobee_sim.simulation import Simulation
from sim_rtf import library_rtf as sim_rtf_library


def library_rtf(solver: str, res: int, seconds: float) -> tuple[float, int]:
    """sim_rtf's library loop with the FEM bag on `solver`: (real-time factor, nodes)."""
    wall, _, nodes = sim_rtf_library("fem", res, seconds, fem_solver=solver)
    return wall, nodes


def batched(res: int, k: int, seconds: float) -> tuple[float, int]:
    """Bag-seconds per wall second of K copies stepped together (each copy its own wrench)."""
    sim = Simulation("node2_to_jem_bag", bag_model="fem", bag_resolution=res, fem_solver="fast")
    try:
        ro = FemRollout.from_bag(sim.bag, sim.robots[""], k, sim.dt)
        rng = np.random.default_rng(0)
        wr = np.c_[rng.uniform(-0.5, 0.5, (k, 3)), rng.uniform(-0.05, 0.05, (k, 3))]
        ro.step(wr, 1)                                   # factor outside the timing
        steps = max(1, int(round(seconds / sim.dt)))
        t0 = time.perf_counter()
        ro.step(wr, steps)
        return k * steps * sim.dt / (time.perf_counter() - t0), sim.bag.num_nodes
    finally:
        sim.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="longer runs")
    a = ap.parse_args()
    s = 3.0 if a.full else 1.0
    rows = []
    for res, secs, target in ((400, 3.0, "3x (goal 10x)"), (1500, 1.0, "1x")):
        fast, n = library_rtf("fast", res, secs * s)
        ref, _ = library_rtf("bullet", res, secs * s / (3 if res > 1000 else 1))
        rows.append((f"library, {n} nodes", fast, ref, f"{target}; pyastrobee 0.6x at 379 nodes"))
    for k in (1, 64):
        thr, n = batched(400, k, (1.0 if k == 1 else 0.15) * s)
        rows.append((f"batched K={k}, {n} nodes (bag-s per wall s)", thr, float("nan"),
                     "rollouts; Bullet: one process per copy"))
    print("\nFEM bag, fast solver vs Bullet's soft body (same run, same machine; wall-clock "
          "real-time factor, PD law dragging the bag)")
    print(f"{'case':<44}{'fast':>9}{'bullet':>9}{'speed-up':>10}  target / reference")
    for name, fast, ref, target in rows:
        ratio = fast / ref if ref == ref else float("nan")
        print(f"{name:<44}{fast:>8.1f}x{ref:>8.2f}x{ratio:>9.1f}x  {target}")


if __name__ == "__main__":
    main()
