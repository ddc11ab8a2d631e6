"""Fly the oracle's plans in the FEM simulator (astrobee_lab.oracle.fly): does the answer hold?

    python bench/oracle_fly.py [--cases 5:0 10:0 5:1] [--nodes 300] [--feedback lqr|pd]
                               [--pair fem|fem_bumped|physical] [--swing] [--replan S] [--margin M]
                               [--bag-margin M] [--react S]
                               [--trace-dir DIR]
    python bench/oracle_fly.py --baseline --cases 2.5:0 5:0     # the project's PD alone

Each case MAGNITUDE:SEED is solved by the oracle (Node 2 -> JEM, nominal, the study's bump of
that seed) on the pair model `--pair` (fem: the identified parameters of
config/reduced_models.yaml, the study's; fem_bumped: fitted on bumped flights; physical: pair_model.PairParams' defaults, the grasp
where the FEM bag is held and bags.yaml's strap figures) and flown: PD on the plan until the
oracle's window, then its wrench + feedback (lqr: the time-varying LQR on the same model).
Prints one row per case and appends them to studies/results/oracle/flown_tracked.csv
(flown.csv: the first round, PD feedback on the robot, the fem pair).
"""
from __future__ import annotations

import argparse
import csv
import os
import time

import numpy as np

from astrobee_control import pair_model as pm
from astrobee_lab.oracle import fly, solve as so, tracking


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", nargs="*", default=["5:0", "10:0", "5:1"])
    ap.add_argument("--nodes", type=int, default=300)
    ap.add_argument("--feedback", default="lqr", choices=["lqr", "pd"])
    ap.add_argument("--pair", default="fem", choices=["fem", "fem_bumped", "physical"])
    ap.add_argument("--swing", action="store_true", help="the LQR weights the bag's swing too (SWING_SCALE)")
    ap.add_argument("--replan", type=float, default=0.0, help="s between replans from the measured state (0: none)")
    ap.add_argument("--margin", type=float, default=so.MARGIN,
                    help="share of the terminal set's thresholds the plan asks for (flown plans want room)")
    ap.add_argument("--bag-margin", type=float, default=so.BAG_MARGIN,
                    help="m the plan keeps the bag's corners off the walls")
    ap.add_argument("--react", type=float, default=None,
                    help="s after the bump's end: the bump not foreknown, the oracle solved then from the "
                         "measured state (fly's react)")
    ap.add_argument("--baseline", action="store_true",
                    help="fly the project's PD alone on each case instead (same Flight, no oracle)")
    ap.add_argument("--trace-dir", default="", help="save each flight's per-tick trace (npz) here")
    ap.add_argument("--out", default="studies/results/oracle/flown_tracked.csv")
    ap.add_argument("--baseline-out", default="studies/results/oracle/pd_baseline_300.csv")
    a = ap.parse_args()
    params = pm.PairParams() if a.pair == "physical" else pm.load(a.pair)
    leg = so.plan_leg("node2_to_jem_bag")
    for case in a.cases:
        mag, seed = float(case.split(":")[0]), int(case.split(":")[1])
        if a.baseline:
            row = baseline(seed, mag, a.nodes)
            print(case, row, flush=True)
            _append(a.baseline_out, {"magnitude": mag, "seed": seed, "pd_success": row.pop("success"),
                                     **{k: round(v, 4) if isinstance(v, float) else v
                                        for k, v in row.items()}})
            continue
        b = so.bump_of_seed(seed, mag)
        t0 = time.perf_counter()
        kw = {"margin": a.margin, "bag_margin": a.bag_margin}
        r = so.solve(leg, params, b, **kw)
        t1 = time.perf_counter()
        flown = fly.fly(r, leg, params, seed, mag, a.nodes, feedback=a.feedback,
                        trace=bool(a.trace_dir), replan=a.replan, solve_kw=kw, react=a.react,
                        scale=tracking.SWING_SCALE if a.swing else None)
        trace = flown.pop("trace", None)
        row = {"magnitude": mag, "seed": seed, "bump_time": b.time, "pair": a.pair,
               "swing_weighted": a.swing, "replan_every": a.replan, "margin": a.margin,
               "bag_margin": a.bag_margin, "react": a.react,
               "oracle_feasible": r.feasible, "oracle_solve_time": round(r.solve_time, 1), **flown,
               "fly_wall_time": round(time.perf_counter() - t1, 1)}
        row["agree"] = row["oracle_feasible"] == row["flown_success"]
        if trace:
            os.makedirs(a.trace_dir, exist_ok=True)
            np.savez(os.path.join(a.trace_dir, f"trace_{mag:g}_{seed}_{a.pair}_{a.feedback}.npz"), **trace)
        print(row, f"total {time.perf_counter() - t0:.0f} s", flush=True)
        _append(a.out, row)


def _append(path: str, row: dict) -> None:
    """One row appended to the CSV at `path` (its header written first when it is new)."""
    new = not os.path.exists(path)
    with open(path, "a", newline="") as f:
        w = csv.DictWriter(f, list(row))
        if new:
            w.writeheader()
        w.writerow(row)


def baseline(seed: int, magnitude: float, nodes: int) -> dict:
    """The project's PD alone on the case (truth state, the seed's bump, the verdict's budget)."""
    from astrobee_lab.flight import Flight
    realism = {"disturbances": [{"target": "bag", "magnitude": magnitude, "duration": 0.2,
                                 "t_min": 10.0, "t_max": 30.0}]}
    with Flight("node2_to_jem_bag", seed=seed, controller="pd", bag_model="fem",
                bag_resolution=nodes, state_source="truth", realism=realism) as fl:
        r = fl.run()
    keys = ("final_position_error", "final_attitude_error", "min_bag_clearance", "time_to_rest")
    return {"success": r.success, "cause": r.cause, **{k: r.metrics.get(k) for k in keys}}


if __name__ == "__main__":
    main()
