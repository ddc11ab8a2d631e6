"""Fly the oracle's plans in the FEM simulator (astrobee_lab.oracle.fly): does the answer hold?

    python bench/oracle_fly.py [--cases 5:0 10:0 10:1] [--nodes 300]

Each case MAGNITUDE:SEED is solved by the oracle (Node 2 -> JEM, nominal, the study's bump of
that seed) and flown: PD on the plan until the oracle's window, then its wrench + feedback.
Prints one row per case (oracle answer, flown verdict, contacts, minimum bag clearance) and
appends them to studies/results/oracle/flown.csv.
"""
from __future__ import annotations

import argparse
import csv
import os
import time

from astrobee_control import pair_model as pm
from astrobee_lab.oracle import fly, solve as so


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", nargs="*", default=["5:0", "10:0", "10:1"])
    ap.add_argument("--nodes", type=int, default=300)
    ap.add_argument("--out", default="studies/results/oracle/flown.csv")
    a = ap.parse_args()
    params = pm.load("fem")
    leg = so.plan_leg("node2_to_jem_bag")
    for case in a.cases:
        mag, seed = float(case.split(":")[0]), int(case.split(":")[1])
        b = so.bump_of_seed(seed, mag)
        t0 = time.perf_counter()
        r = so.solve(leg, params, b)
        t1 = time.perf_counter()
        row = {"magnitude": mag, "seed": seed, "bump_time": b.time, "oracle_feasible": r.feasible,
               "oracle_solve_time": round(r.solve_time, 1), **fly.fly(r, leg, params, seed, mag, a.nodes),
               "fly_wall_time": round(time.perf_counter() - t1, 1)}
        row["agree"] = row["oracle_feasible"] == row["flown_success"]
        print(row, f"total {time.perf_counter() - t0:.0f} s", flush=True)
        new = not os.path.exists(a.out)
        with open(a.out, "a", newline="") as f:
            w = csv.DictWriter(f, list(row))
            if new:
                w.writeheader()
            w.writerow(row)


if __name__ == "__main__":
    main()
