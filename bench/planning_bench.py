"""Planning benchmark: global planner time and trajectory duration per module pair, local
planner time per call, beside pyastrobee's figures (FACTS.md section 6)."""
from __future__ import annotations

import argparse
import itertools
import sys
import time

import numpy as np

from astrobee import config
from astrobee import rotations as rot
from astrobee_planning import boxes, local_planner, multi_robot, planner

REF = {("node_2", "jem"): "1.8 s", ("jem", "node_1"): "4.3 s", ("jem", "cupola"): "10.1 s (287 s traj)"}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--full", action="store_true", help="all ordered module pairs (default: unordered)")
    ap.add_argument("--mode", default="nominal")
    args = ap.parse_args(argv)
    ss = boxes.safe_set()
    wps = {k: np.array(v, float) for k, v in config.iss()["waypoints"].items() if ss.contains(np.array(v))}
    pairs = list(REF)
    others = itertools.permutations(sorted(wps), 2) if args.full else itertools.combinations(sorted(wps), 2)
    pairs += [p for p in others if p not in REF and p[::-1] not in REF]
    q = rot.IDENTITY
    print(f"global planner ({args.mode}, rest to rest, orientation held)")
    print(f"{'pair':<22}{'segs':>6}{'plan (s)':>10}{'traj (s)':>10}  pyastrobee")
    for a, b in pairs:
        t = time.perf_counter()
        plan = planner.plan_global(wps[a], q, wps[b], q, args.mode, safe=ss)
        dt = time.perf_counter() - t
        print(f"{a + ' -> ' + b:<22}{len(plan.route):>6}{dt:>10.3f}{plan.trajectory.duration:>10.1f}  {REF.get((a, b), '-')}")
    print("\ntwo robots + bag (0.8 m apart in line, default bag; rest to rest, bag orientation held)")
    print(f"{'pair':<22}{'steps':>6}{'plan (s)':>10}{'traj (s)':>10}  round one")
    before = {("node_2", "jem"): "340 s", ("node_1", "node_3"): "PLAN_FAILED"}
    for a, b in [("node_2", "jem"), ("node_1", "node_3"), ("us_lab", "node_2"), ("node_2", "eu_lab"),
                 ("jem", "node_1")]:
        t = time.perf_counter()
        try:
            f = multi_robot.plan_two_robots(wps[a], q, wps[b], q, [0.4, 0.0, 0.0], args.mode)
            res = f"{len(f.steps):>6}{time.perf_counter() - t:>10.3f}{f.centre.trajectory.duration:>10.1f}"
        except planner.PlanError as exc:
            res = f"{'-':>6}{time.perf_counter() - t:>10.3f}{'failed':>10}  ({exc})"
        print(f"{a + ' -> ' + b:<22}{res}  {before.get((a, b), '-')}")
    rng = np.random.default_rng(0)

    def state():
        return {"pos": rng.normal(size=3), "vel": rng.normal(size=3) * 0.1, "acc": rng.normal(size=3) * 0.01,
                "quat": rot.normalize(rng.normal(size=4)), "omega": rng.normal(size=3) * 0.1,
                "alpha": rng.normal(size=3) * 0.05}
    s0, s1 = state(), state()
    n = 2000
    t = time.perf_counter()
    for _ in range(n):
        local_planner.plan(s0, s1, 5.0)
    single = (time.perf_counter() - t) / n
    keys = ("pos", "vel", "acc", "quat", "omega", "alpha")
    flat = [s0[k] for k in keys] + [s1[k] for k in keys]
    t = time.perf_counter()
    for _ in range(n):
        local_planner.plan_single(*flat, 5.0)
    raw = (time.perf_counter() - t) / n
    N = 1000
    keys = ("pos", "vel", "acc", "quat", "omega", "alpha")
    st = [state() for _ in range(2)]
    arr = [np.tile(st[i][k], (N, 1)) for i in range(2) for k in keys]
    t = time.perf_counter()
    reps = 20
    for _ in range(reps):
        local_planner.plan_batch(*arr, np.full(N, 5.0))
    batch = (time.perf_counter() - t) / (reps * N)
    print("\nlocal planner (5 s horizon)        ours        pyastrobee")
    print(f"{'plan() -> Trajectory':<30}{single * 1e3:>9.4f} ms   ~75 ms")
    print(f"{'plan_single (arrays)':<30}{raw * 1e3:>9.4f} ms   ~75 ms")
    print(f"{'batched, per plan (N=1000)':<30}{batch * 1e3:>9.4f} ms   ~75 ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
