"""Fast FEM solver vs Bullet's soft body: library real-time factor while a PD law drags the bag,
and batched rollouts (K copies of robot + bag in one step call), in bag-seconds per wall second.

The K=64 rows are an A/B of the robot-wall contact in the rollouts (fem_rollout + rigid_walls):
off, on in open space (sim_rtf's batched setup: Node 2, random wrenches), and on with every
copy pressed against Node 2's ceiling (the worst case: all 64 in contact every step), in
bag-seconds per wall second and per CPU second, rounds interleaved, beside sim_rtf.py's
13.4 bag-s per wall s (README; before the contact).

Same loop as bench/sim_rtf.py's library column (physics at 350 Hz, one PD command per 16 ms
tick, bag state + clearance + contacts read every tick), both solvers in the same run.
Targets: ~400 nodes >= 3x real time (goal 10x), ~1500 nodes >= 1x.

    .venv/bin/python bench/fem_fast_bench.py [--full]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from sim_rtf import batched_rtf as batched
from sim_rtf import library_rtf as sim_rtf_library

REF_BATCHED = 13.4          # bag-s per wall s, K=64, 412 nodes, README (sim_rtf.py, before walls)
CEILING_LIFT = 1.157        # m: Node 2 start lifted so the robot box is ~1 mm below the ceiling


def library_rtf(solver: str, res: int, seconds: float) -> tuple[float, float, int]:
    """sim_rtf's library loop with the FEM bag on `solver`: (wall and CPU real-time factors,
    nodes). The CPU figure (sim seconds per CPU second of this process) holds better than the
    wall one on a machine shared with other work."""
    return sim_rtf_library("fem", res, seconds, fem_solver=solver)


def batched_walls(res: int, k: int, seconds: float, rounds: int = 5) -> dict:
    """Bag-seconds per wall and per CPU second (medians over interleaved rounds) of K copies of
    robot + fast FEM bag: robot-wall contact off, on in open space, on against the ceiling."""
    from astrobee_sim.bags.fem_rollout import FemRollout
    from astrobee_sim.simulation import Simulation
    sim = Simulation("node2_to_jem_bag", bag_model="fem", bag_resolution=res, fem_solver="fast")
    try:
        robot = sim.robots[""]
        rng = np.random.default_rng(0)
        wr = np.c_[rng.uniform(-0.5, 0.5, (k, 3)), rng.uniform(-0.05, 0.05, (k, 3))]
        pos, q, _, _ = robot.state()
        open_ = FemRollout.from_bag(sim.bag, robot, k, sim.dt).snapshot()
        lift = np.array([0.0, 0.0, CEILING_LIFT])
        robot.set_pose(pos + lift, q)
        sim.bag.x += lift
        wall = FemRollout.from_bag(sim.bag, robot, k, sim.dt).snapshot()
        up = wr.copy()
        up[:, 2] = rng.uniform(0.2, 0.5, k)          # body +z is world +z here: pressed up
        cases = {"off": (open_, wr, False), "on, open space": (open_, wr, True),
                 "on, all pressed to the ceiling": (wall, up, True)}
        ros = {}
        for name, (snap, w, walls) in cases.items():
            ro = FemRollout.from_bag(sim.bag, robot, k, sim.dt, robot_walls=walls)
            ro.restore(snap)
            # warm-up outside the timing; pressed: past the first touch and its rebound
            ro.step(w, 20 if snap is wall else 1)
            ros[name] = (ro, ro.snapshot(), w)
        steps = max(1, int(round(seconds / sim.dt)))
        res_: dict = {n: ([], [], []) for n in cases}
        for _ in range(rounds):
            for name, (ro, snap, w) in ros.items():
                ro.restore(snap)
                t0, c0 = time.perf_counter(), time.process_time()
                ro.step(w, steps)
                dw, dc = time.perf_counter() - t0, time.process_time() - c0
                res_[name][0].append(k * steps * sim.dt / dw)
                res_[name][1].append(k * steps * sim.dt / max(dc, 1e-9))
                res_[name][2].append(float((ro.wall_depth > 0).mean()))
        return {n: (float(np.median(a)), float(np.median(b)), float(np.mean(c)), sim.bag.num_nodes)
                for n, (a, b, c) in res_.items()}
    finally:
        sim.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="longer runs")
    a = ap.parse_args()
    s = 3.0 if a.full else 1.0
    rows = []
    for res, secs, target in ((400, 3.0, "3x (goal 10x)"), (1500, 1.0, "1x")):
        fast, fast_cpu, n = library_rtf("fast", res, secs * s)
        ref, ref_cpu, _ = library_rtf("bullet", res, secs * s / (3 if res > 1000 else 1))
        rows.append((f"library, {n} nodes", fast, fast_cpu, ref, ref_cpu,
                     f"{target}; pyastrobee 0.6x at 379 nodes"))
    thr, n = batched(400, 1, 1.0 * s)
    rows.append((f"batched K=1, {n} nodes (bag-s per wall s)", thr, float("nan"),
                 float("nan"), float("nan"), "rollouts; Bullet: one process per copy"))
    ab = batched_walls(400, 64, 0.15 * s)
    print("\nFEM bag, fast solver vs Bullet's soft body (same run, same machine; real-time factor "
          "by the wall clock and per CPU second, PD law dragging the bag)")
    print(f"{'case':<44}{'fast':>8}{'cpu':>8}{'bullet':>8}{'cpu':>8}{'speed-up':>10}  target / reference")
    for name, fast, fast_cpu, ref, ref_cpu, target in rows:
        ratio = fast_cpu / ref_cpu if ref_cpu == ref_cpu else float("nan")
        print(f"{name:<44}{fast:>7.1f}x{fast_cpu:>7.1f}x{ref:>7.2f}x{ref_cpu:>7.2f}x{ratio:>9.1f}x  {target}")
    print(f"\nbatched K=64 copies of robot + bag, robot-wall contact off / on (interleaved "
          f"rounds, medians); reference {REF_BATCHED} bag-s per wall s (sim_rtf.py, README, "
          f"before the contact)")
    print(f"{'robot-wall contact':<34}{'nodes':>6}{'bag-s/wall s':>14}{'bag-s/CPU s':>13}"
          f"{'vs off (CPU)':>13}{'copies touching':>17}")
    base = ab["off"][1]
    for name, (wall_thr, cpu_thr, touching, n) in ab.items():
        print(f"{name:<34}{n:>6}{wall_thr:>14.1f}{cpu_thr:>13.1f}{cpu_thr / base:>12.2f}x"
              f"{touching:>16.0%}")


if __name__ == "__main__":
    main()
