"""The oracle's feasibility per bump size on Node 2 -> JEM (nominal mode, strap grasp's reduced
pair model): bumps of 2.5 / 5 / 7.5 / 10 N for 0.2 s on the bag at the study runner's seeded
time U(10, 30) s and direction (astrobee_lab.oracle.solve.bump_of_seed), seeds 0..19.

    python studies/oracle_feasibility.py [--seeds 20] [--first-seed 0] [--out studies/results/oracle/feasibility.csv]
    python studies/oracle_feasibility.py --table      # the table over every study file
    python studies/oracle_feasibility.py --pair fem_bumped --magnitudes 10 5 \
        --out studies/results/oracle/feasibility_bumped.csv   # the model fitted on bumped flights

Resumable: rows already in the CSV are skipped. Prints the table of docs/results/oracle.md.
A second process writes feasibility_<letter>.csv: the files astrobee_lab.oracle.load_feasibility
reads (a variant of the problem gets another name, e.g. feasibility_margin0.csv, and is not read).
"""
from __future__ import annotations

import argparse
import csv
import os
import statistics
import time
from pathlib import Path

from astrobee_control import pair_model as pm
from astrobee_lab.oracle import solve as so
from astrobee_lab.oracle.feasibility import study_files

MAGNITUDES = (2.5, 5.0, 7.5, 10.0)
FIELDS = ["magnitude", "seed", "bump_time", "fx", "fy", "fz", "feasible", "status", "solve_time",
          "nodes", "box", "goal", "attitude", "rest_speed", "rest_omega"]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--out", default="studies/results/oracle/feasibility.csv")
    ap.add_argument("--magnitudes", type=float, nargs="*", default=list(MAGNITUDES))
    ap.add_argument("--pair", default="fem", help="the pair parameters (config/reduced_models.yaml "
                    "`pair:`): fem (the study's), fem_bumped (fitted on bumped flights)")
    ap.add_argument("--seed-list", type=int, nargs="*", help="these seeds (instead of "
                    "--first-seed .. --seeds)")
    ap.add_argument("--margin", type=float, default=so.MARGIN, help="the share of the terminal "
                    "set's thresholds the NLP asks for (a variant: give it its own --out)")
    ap.add_argument("--mode-limits", action="store_true", help="the robot's speed and rate "
                    "also within the flight mode's hard limits (a variant: give it its own --out)")
    ap.add_argument("--table", action="store_true", help="only print the table of the study files "
                    "(with --out naming a variant's CSV: that file's)")
    a = ap.parse_args()
    if not 0 < a.margin <= 1:
        ap.error(f"--margin must be in (0, 1], got {a.margin}")
    study = study_files(os.path.dirname(a.out) or ".")
    if a.table:                         # a variant's CSV is read alone, the study's files together
        table(*(study if Path(a.out) in study or not os.path.exists(a.out) else [a.out]))
        return
    try:
        params = pm.load(a.pair)
    except ValueError as e:
        ap.error(f"--pair: {e}")
    leg = so.plan_leg("node2_to_jem_bag")
    done = set()
    if os.path.exists(a.out):
        with open(a.out) as f:
            done = {(float(r["magnitude"]), int(r["seed"])) for r in csv.DictReader(f)}
    new = not os.path.exists(a.out)
    with open(a.out, "a", newline="") as f:
        w = csv.DictWriter(f, FIELDS + (["speed_max", "rate_max"] if a.mode_limits else []))
        if new:
            w.writeheader()
        seeds = a.seed_list if a.seed_list else range(a.first_seed, a.seeds)
        for seed in seeds:          # seed-major: a partial run covers every size
            for mag in a.magnitudes:
                if (mag, seed) in done:
                    continue
                b = so.bump_of_seed(seed, mag)
                t = time.perf_counter()
                r = so.solve(leg, params, b, mode_limits=a.mode_limits, margin=a.margin)
                row = {"magnitude": mag, "seed": seed, "bump_time": b.time,
                       "fx": round(b.force[0], 4), "fy": round(b.force[1], 4),
                       "fz": round(b.force[2], 4), **r.row()}
                w.writerow(row)
                f.flush()
                print(row, f"{time.perf_counter() - t:.1f}s", flush=True)
    table(a.out)


def table(*paths: str) -> None:
    """The table of docs/results/oracle.md: feasible / seeds (Wilson 95%) and solve times."""
    rows: dict = {}
    for path in paths:
        with open(path) as f:
            for r in csv.DictReader(f):
                rows.setdefault((float(r["magnitude"]), int(r["seed"])), r)
    print("| bump (N) | feasible / seeds | Wilson 95% | median solve time (s) | max solve time (s) |")
    print("|---|---|---|---|---|")
    for mag in sorted({m for m, _ in rows}):
        rs = [r for (m, _), r in rows.items() if m == mag]
        ok = sum(r["feasible"] == "True" for r in rs)
        lo, hi = wilson(ok, len(rs))
        ts = [float(r["solve_time"]) for r in rs]
        print(f"| {mag:g} | {ok} / {len(rs)} | {100 * lo:.0f}%-{100 * hi:.0f}% | "
              f"{statistics.median(ts):.1f} | {max(ts):.1f} |")


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of k successes in n."""
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * ((p * (1 - p) / n + z * z / (4 * n * n)) ** 0.5) / d
    return max(0.0, c - h), min(1.0, c + h)


if __name__ == "__main__":
    main()
