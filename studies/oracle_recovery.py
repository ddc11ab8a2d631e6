"""Write out one oracle recovery: the optimal plan for one seed's bump, node by node.

Per grid node: the robot's distance from the plan, its attitude error and rate, the wrench.

    python studies/oracle_recovery.py --seed 230 --magnitude 7.5 \
        --out studies/results/oracle/recovery_230_7.5.csv

The problem is studies/oracle_feasibility.py's (astrobee_lab.oracle.solve, Node 2 -> JEM, the
seed's bump), on the pair model named by --pair (default fem_bumped, the one feasibility_bumped.csv
was solved on). Prints the row of the answer and every 2nd grid node of the plan.
"""
from __future__ import annotations

import argparse
import csv

import numpy as np

from astrobee import rotations as rot
from astrobee_control import pair_model as pm
from astrobee_lab.oracle import solve as so

FIELDS = ["t", "dx", "dy", "dz", "distance", "attitude_error", "bag_attitude_error", "rate",
          "fx", "fy", "fz", "tx", "ty", "tz"]


def recovery_rows(res: so.OracleResult, leg: so.Leg, params: pm.PairParams) -> list[dict]:
    """Per grid node: the robot's offset from the planned state (m, world), its attitude error
    and the bag's against the plan (rad), the robot's rate (rad/s) and the commanded wrench."""
    rows = []
    for i, t in enumerate(res.t):
        ps = so.planned_state(leg, params, float(t))
        dp = res.x[i, pm.P_R] - ps[pm.P_R]
        u = res.u[min(i, len(res.u) - 1)]
        rows.append({"t": round(float(t), 3), "dx": round(float(dp[0]), 4),
                     "dy": round(float(dp[1]), 4), "dz": round(float(dp[2]), 4),
                     "distance": round(float(np.linalg.norm(dp)), 4),
                     "attitude_error": round(rot.angle_between(res.x[i, pm.Q_R], ps[pm.Q_R]), 4),
                     "bag_attitude_error": round(rot.angle_between(res.x[i, pm.Q_B],
                                                                   ps[pm.Q_B]), 4),
                     "rate": round(float(np.linalg.norm(res.x[i, pm.W_R])), 4),
                     **{k: round(float(v), 5) for k, v in zip(FIELDS[8:], u)}})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--magnitude", type=float, required=True)
    ap.add_argument("--pair", default="fem_bumped")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    try:
        params = pm.load(a.pair)
    except ValueError as e:
        ap.error(f"--pair: {e}")
    leg = so.plan_leg("node2_to_jem_bag")
    res = so.solve(leg, params, so.bump_of_seed(a.seed, a.magnitude))
    rows = recovery_rows(res, leg, params)
    with open(a.out, "w", newline="") as f:
        w = csv.DictWriter(f, FIELDS)
        w.writeheader()
        w.writerows(rows)
    print(res.row())
    for r in rows[::2]:
        print(f"t {r['t']:6.1f}  off the plan {r['distance']:.2f} m  attitude {r['attitude_error']:.2f}"
              f" rad  rate {r['rate']:.2f} rad/s  |F| {np.hypot.reduce([r['fx'], r['fy'], r['fz']]):.2f}"
              f" N  |T| {np.hypot.reduce([r['tx'], r['ty'], r['tz']]):.3f} N m")


if __name__ == "__main__":
    main()
