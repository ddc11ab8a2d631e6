"""Fast FEM solver vs Bullet's soft body: library real-time factor while a PD law drags the bag,
and batched rollouts (K copies of robot + bag in one step call), in bag-seconds per wall second.

Same loop as bench/sim_rtf.py's library column (physics at 350 Hz, one PD command per 16 ms
tick, bag state + clearance + contacts read every tick), both solvers in the same run.
Targets (issue 12): ~400 nodes >= 3x real time (goal 10x), ~1500 nodes >= 1x.

    .venv/bin/python bench/fem_fast_bench.py [--full]
"""
from __future__ import annotations

import argparse

from sim_rtf import batched_rtf as batched
from sim_rtf import library_rtf as sim_rtf_library


def library_rtf(solver: str, res: int, seconds: float) -> tuple[float, float, int]:
    """sim_rtf's library loop with the FEM bag on `solver`: (wall and CPU real-time factors,
    nodes). The CPU figure (sim seconds per CPU second of this process) holds better than the
    wall one on a machine shared with other work."""
    return sim_rtf_library("fem", res, seconds, fem_solver=solver)


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
    for k in (1, 64):
        thr, n = batched(400, k, (1.0 if k == 1 else 0.15) * s)
        rows.append((f"batched K={k}, {n} nodes (bag-s per wall s)", thr, float("nan"),
                     float("nan"), float("nan"), "rollouts; Bullet: one process per copy"))
    print("\nFEM bag, fast solver vs Bullet's soft body (same run, same machine; real-time factor "
          "by the wall clock and per CPU second, PD law dragging the bag)")
    print(f"{'case':<44}{'fast':>8}{'cpu':>8}{'bullet':>8}{'cpu':>8}{'speed-up':>10}  target / reference")
    for name, fast, fast_cpu, ref, ref_cpu, target in rows:
        ratio = fast_cpu / ref_cpu if ref_cpu == ref_cpu else float("nan")
        print(f"{name:<44}{fast:>7.1f}x{fast_cpu:>7.1f}x{ref:>7.2f}x{ref_cpu:>7.2f}x{ratio:>9.1f}x  {target}")


if __name__ == "__main__":
    main()
