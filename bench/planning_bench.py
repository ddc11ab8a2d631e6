"""Planning benchmark: global planner per route (plan time, plan + 350 Hz sampling, trajectory
duration, time-optimality gap against the trapezoid lower bound, QP solves and interior-point
iterations, peak speed against the flight mode's limit) and 350 Hz sampling alone, beside the paper's
code (pyastrobee, measured side by side), two-robot formation plans beside the
single-robot ones, and the local planner (plan + 350 Hz samples of a 5 s plan)."""
from __future__ import annotations

import argparse
import itertools
import os
import sys
import time

import numpy as np

from astrobee import config, flight_modes
from astrobee import rotations as rot
from astrobee_planning import local_planner, multi_robot, planner

RATE = 350.0      # Hz, the paper's sampling rate
# the paper's code on the same machine, plan + 350 Hz samples / its trajectory (s)
PAPER = {("node_2", "jem"): (4.75, 60.5), ("jem", "node_1"): (9.72, 199.3),
         ("jem", "cupola"): (16.05, 273.3), ("eu_lab", "jem"): (6.14, 98.8),
         ("us_lab", "node_3"): (8.49, 87.6)}
PAPER_LOCAL = 189.0   # ms, local planner 5 s plan + samples
TARGET = 0.1          # s, every route's plan + 350 Hz samples on a quiet machine
FORMATION = [("node_2", "jem"), ("node_1", "node_3"), ("us_lab", "node_2"), ("node_2", "eu_lab"),
             ("jem", "node_1")]
FORMATION_BEFORE = {("node_2", "jem"): "1.0-1.3 s", ("node_1", "node_3"): "0.7-3 s"}


def _median_time(f, reps: int) -> tuple[float, object]:
    ts, out = [], None
    for _ in range(reps):
        t = time.perf_counter()
        out = f()
        ts.append(time.perf_counter() - t)
    return float(np.median(ts)), out


def global_routes(wps, pairs, mode, safe, reps) -> None:
    q = rot.IDENTITY
    vmax = flight_modes.get(mode).hard_limit_vel
    print(f"global planner ({mode}, rest to rest, orientation held; median of {reps}); "
          f"target plan + 350 Hz samples <= {TARGET:.1f} s")
    print(f"{'route':<20}{'plan':>8}{'+350Hz':>8}{'paper':>8}{'ratio':>7}{'traj':>8}{'paper':>8}"
          f"{'bound':>8}{'gap':>6}{'solves':>7}{'iters':>6}{'v/vmax':>8}")
    for a, b in pairs:
        tp, plan = _median_time(lambda: planner.plan_global(wps[a], q, wps[b], q, mode, safe=safe), reps)
        ts, st = _median_time(lambda: planner.plan_global(wps[a], q, wps[b], q, mode, safe=safe)
                              .trajectory.sample_rate(RATE), reps)
        tr = plan.trajectory
        lb = tr.info.get("lower_bound", 0.0)
        gap = f"{100 * (tr.duration / lb - 1):.0f}%" if lb else "-"
        vpk = float(np.max(np.linalg.norm(st.vel, axis=1)))
        ref = PAPER.get((a, b))
        pt, pd = (f"{ref[0]:.2f}", f"{ref[1]:.1f}") if ref else ("-", "-")
        ratio = f"{ref[0] / ts:.0f}x" if ref else "-"
        flag = "" if ts <= TARGET else " (over target)"
        print(f"{a + ' -> ' + b:<20}{tp:>8.3f}{ts:>8.3f}{pt:>8}{ratio:>7}{tr.duration:>8.1f}{pd:>8}"
              f"{lb:>8.1f}{gap:>6}{tr.info.get('solves', 0):>7}{tr.info.get('qp_iterations', 0):>6}"
              f"{vpk / vmax:>8.3f}{flag}")


def long_sampling(wps, pairs, mode, safe, reps) -> None:
    """The global trajectories' samples at 350 Hz (plain and face-forward: one attitude piece a
    segment), median and best of reps."""
    print(f"\nsampling global trajectories at {RATE:.0f} Hz (median / best of {reps}); target: a few ms")
    print(f"{'route':<20}{'attitude':>13}{'pieces':>8}{'states':>8}{'median':>9}{'best':>8}{'ns/state':>9}")
    for a, b in pairs:
        for ff in (False, True):
            plan = planner.plan_global(wps[a], rot.IDENTITY, wps[b], rot.IDENTITY, mode, face_forward=ff,
                                       safe=safe)
            tr = plan.trajectory
            ts = []
            for _ in range(reps):
                t = time.perf_counter()
                st = tr.sample_rate(RATE)
                ts.append(time.perf_counter() - t)
            med = float(np.median(ts))
            print(f"{a + ' -> ' + b:<20}{'face-forward' if ff else 'blend':>13}"
                  f"{len(tr.position):>4}+{len(tr.attitude):<3}{len(st):>8}{med * 1e3:>7.1f}ms"
                  f"{min(ts) * 1e3:>6.1f}ms{med / len(st) * 1e9:>9.0f}")


def formations(wps, mode, safe, reps) -> None:
    q = rot.IDENTITY
    print(f"\ntwo robots + bag (0.8 m apart in line, default bag; median of {reps}); target plan <= 0.5 s;"
          "\n'held': turns made holding position (the others overlap the legs' braking and speeding up)")
    print(f"{'route':<20}{'plan':>8}{'traj':>8}{'turns':>7}{'held':>6}{'1 robot':>9}{'1r traj':>9}  before")
    for a, b in FORMATION:
        single, sp = _median_time(lambda: planner.plan_global(wps[a], q, wps[b], q, mode, safe=safe), reps)
        try:
            t, f = _median_time(lambda: multi_robot.plan_two_robots(wps[a], q, wps[b], q,
                                                                    [0.4, 0.0, 0.0], mode), reps)
            turns = sum(s.startswith("turn") for s in f.steps)
            stops = sum(s.startswith("turn") and "while moving" not in s for s in f.steps)
            res = f"{t:>8.3f}{f.centre.trajectory.duration:>8.1f}{turns:>7}{stops:>6}"
        except planner.PlanError as exc:
            res = f"{'-':>8}{'failed':>8}{'':>14}  ({exc})"
        print(f"{a + ' -> ' + b:<20}{res}{single:>9.3f}{sp.trajectory.duration:>9.1f}  "
              f"{FORMATION_BEFORE.get((a, b), '-')}")


def local(reps: int = 300) -> None:
    rng = np.random.default_rng(0)

    def state():
        return {"pos": rng.normal(size=3), "vel": rng.normal(size=3) * 0.1, "acc": rng.normal(size=3) * 0.01,
                "quat": rot.normalize(rng.normal(size=4)), "omega": rng.normal(size=3) * 0.1,
                "alpha": rng.normal(size=3) * 0.05}
    s0, s1 = state(), state()
    plan_t, tr = _median_time(lambda: local_planner.plan(s0, s1, 5.0), reps)
    samp_t, st = _median_time(lambda: tr.sample_rate(RATE), reps)
    both_t, _ = _median_time(lambda: local_planner.plan(s0, s1, 5.0).sample_rate(RATE), reps)
    N = 1000
    keys = ("pos", "vel", "acc", "quat", "omega", "alpha")
    arr = [np.tile(s[k], (N, 1)) for s in (s0, s1) for k in keys]
    batch_t, _ = _median_time(lambda: local_planner.plan_batch(*arr, np.full(N, 5.0)), 20)
    print(f"\nlocal planner, 5 s plan ({len(st)} samples at {RATE:.0f} Hz; median of {reps})")
    print(f"{'':<34}{'ours':>10}{'paper':>10}{'ratio':>8}  target")
    print(f"{'plan()':<34}{plan_t * 1e3:>8.3f}ms{'':>10}")
    print(f"{'350 Hz sampling':<34}{samp_t * 1e3:>8.3f}ms{'':>18}  <= 0.2 ms")
    print(f"{'plan + 350 Hz samples':<34}{both_t * 1e3:>8.3f}ms{PAPER_LOCAL:>8.0f}ms"
          f"{PAPER_LOCAL / (both_t * 1e3):>7.0f}x  <= 0.3 ms (>= 100x)")
    print(f"{'batched plans, per plan (N=1000)':<34}{batch_t / N * 1e3:>8.4f}ms")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--all", action="store_true", help="every unordered module pair too")
    ap.add_argument("--mode", default="nominal")
    ap.add_argument("--reps", type=int, default=3)
    args = ap.parse_args(argv)
    safe = planner.cached_safe_set(0.0)
    wps = {k: np.array(v, float) for k, v in config.iss()["waypoints"].items()
           if safe.contains(np.array(v, float))}
    pairs = list(PAPER)
    if args.all:
        pairs += [p for p in itertools.combinations(sorted(wps), 2) if p not in PAPER and p[::-1] not in PAPER]
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"load average {load:.1f} on {os.cpu_count()} cores (figures scale with it)\n")
    global_routes(wps, pairs, args.mode, safe, args.reps)
    long_sampling(wps, list(PAPER), args.mode, safe, max(args.reps, 5))
    formations(wps, args.mode, safe, args.reps)
    local()
    return 0


if __name__ == "__main__":
    sys.exit(main())
