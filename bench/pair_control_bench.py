"""Decision time of the wrench MPC (controller:=wmpc) and per-tick time of the pair law
(controller:=pair), the governed pair law (controller:=pair_gov) and the wrench allocation,
on one core, robot + 10 kg bag in Node 2 on a 30 s leg of 2 m towards the JEM (real keep-in
boxes), the state following the plan with noise (each decision warm-started from the last), and
a spun case (the pair turned 0.3 rad, turning at 0.1 rad/s). Prints median and p99 beside the 50 ms target.

    .venv/bin/python bench/pair_control_bench.py [--repeats 60]
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from astrobee import config, flight_modes  # noqa: E402
from astrobee import rotations as rot  # noqa: E402
from astrobee_control import allocation as al  # noqa: E402
from astrobee_control import mass as mp  # noqa: E402
from astrobee_control.law import BagObservation  # noqa: E402
from astrobee_control.pair_governor import make_gov_law  # noqa: E402
from astrobee_control.pair_law import make_pair_law  # noqa: E402
from astrobee_control.pd import State  # noqa: E402
from astrobee_control.reference import rest_to_rest  # noqa: E402
from astrobee_control.wrench_mpc import make_wrench_mpc_law  # noqa: E402

Q = np.array([0.0, 0.0, -0.7071067811865476, 0.7071067811865476])
P0 = np.array([10.95, 0.0, 4.84])
OFFSET = np.array([-0.484, 0.0, -0.065])
TARGET_MS = 50.0
ROOT = Path(__file__).resolve().parents[1]


def state_and_bag(p, v, q, w, rng):
    st = State(p + rng.normal(0, 0.005, 3), v + rng.normal(0, 0.002, 3), q, w)
    bag = BagObservation(st.position + rot.rotate(q, OFFSET), q, st.velocity, np.zeros(3),
                         True, 10.0, np.array([0.5, 0.42, 0.25]), "constraint")
    return st, bag


def mpc_times(repeats: int, spun: bool) -> np.ndarray:
    fm = flight_modes.get("nominal")
    law = make_wrench_mpc_law(fm, mp.robot(), {})
    rng = np.random.default_rng(0)
    q = rot.multiply(Q, rot.from_rotvec(np.array([0.0, 0.3, 0.0]))) if spun else Q
    w = np.array([0.0, 0.1, 0.0]) if spun else np.zeros(3)
    st, bag = state_and_bag(P0, np.zeros(3), q, w, rng)
    law.update(st, 0.0, 0.016)
    law.observe_bag(bag, st)
    law.follow(rest_to_rest(P0, P0 + [0.0, -2.0, 0.0], Q, Q, 30.0), 0.0)
    out = []
    p, v = P0.copy(), np.zeros(3)
    for i in range(repeats):
        now = 0.2 * i
        if law.plan is not None:      # the state follows the last plan
            p = np.interp(now, law.plan.t, law.plan.robot[:, 0]), \
                np.interp(now, law.plan.t, law.plan.robot[:, 1]), \
                np.interp(now, law.plan.t, law.plan.robot[:, 2])
            p = np.array(p)
        st, bag = state_and_bag(p, v, q, w, rng)
        law.observe_bag(bag, st)
        c0 = time.process_time()
        plan = law.decide(st, now)
        out.append(time.process_time() - c0)
        if plan is not None:
            law.plan = plan
    return np.asarray(out[2:]) * 1e3


def pair_tick_times(repeats: int, make=None, params: dict | None = None) -> np.ndarray:
    """Per-tick CPU time (ms) of a law (the pair law unless `make` builds another, with
    `params`) on a 2 m leg with the pair turned and spun at random around the start."""
    fm = flight_modes.get("nominal")
    law = (make or make_pair_law)(fm, mp.robot(), dict(params or {}))
    rng = np.random.default_rng(1)
    st, bag = state_and_bag(P0, np.zeros(3), Q, np.zeros(3), rng)
    law.update(st, 0.0, 0.016)
    law.observe_bag(bag, st)
    law.follow(rest_to_rest(P0, P0 + [0.0, -2.0, 0.0], Q, Q, 30.0), 0.0)
    out = []
    for i in range(repeats):
        st, bag = state_and_bag(P0, np.zeros(3), rot.multiply(Q, rot.from_rotvec(
            rng.normal(0, 0.2, 3))), rng.normal(0, 0.05, 3), rng)
        c0 = time.process_time()
        law.update(st, 0.016 * i, 0.016)
        law.observe_bag(bag, st)
        out.append(time.process_time() - c0)
    return np.asarray(out) * 1e3


def allocation_times(repeats: int) -> tuple[np.ndarray, np.ndarray]:
    from scipy.optimize import lsq_linear
    fm = flight_modes.get("nominal")
    f_lim, t_lim = np.asarray(fm.max_force, float), np.asarray(fm.max_torque, float)
    rng = np.random.default_rng(2)
    cases = [al.problem(rng.uniform(-3, 3, 3) * f_lim, rng.uniform(-3, 3, 3) * t_lim,
                        [-0.25, 0.0, -0.03], f_lim, t_lim, 1.0, 30.0) for _ in range(repeats)]
    ours, scipy_ = [], []
    box = (-np.ones(6), np.ones(6))
    for A, b in cases:
        c0 = time.process_time()
        al.box_lsq(A, b)
        ours.append(time.process_time() - c0)
        c0 = time.process_time()
        lsq_linear(A, b, bounds=box, method="bvls")
        scipy_.append(time.process_time() - c0)
    return np.asarray(ours) * 1e6, np.asarray(scipy_) * 1e6


def row(name: str, ms: np.ndarray, unit: str = "ms", target: str = "") -> None:
    print(f"{name:<44} median {np.median(ms):7.2f} {unit}  p99 {np.percentile(ms, 99):7.2f} "
          f"{unit}  (n={len(ms)}){target}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=60)
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})   # one core
    print(f"load average {os.getloadavg()[0]:.1f} (2 cores shared); CPU time of this process")
    row("wmpc decision (CPU), following its plan", mpc_times(args.repeats, False),
        target=f"   target <= {TARGET_MS:g} ms median")
    row("wmpc decision (CPU), pair spun 0.3 rad", mpc_times(args.repeats, True),
        target=f"   target <= {TARGET_MS:g} ms median")
    row("pair law tick (CPU, update + observe_bag)", pair_tick_times(20 * args.repeats),
        target="   budget 16 ms a tick (62.5 Hz)")
    row("governed pair law tick (CPU, pair_gov)", pair_tick_times(20 * args.repeats, make_gov_law),
        target="   budget 16 ms a tick; target <= 50 ms")
    row("pair_gov, lever + clearance 0.3 (CPU)",
        pair_tick_times(20 * args.repeats, make_gov_law, {"lever": True, "clearance": 0.3}),
        target="   budget 16 ms a tick; target <= 50 ms")
    for law in ("gov_bag", "gov_mom", "gov_uwm"):   # the parameters the scenarios (the demo) fly
        params = config.scenario(f"node2_to_jem_fem_bag_{law}")["controller_params"]
        row(f"{law} tick (CPU, its scenario's params)",
            pair_tick_times(20 * args.repeats, make_gov_law, params),
            target="   budget 16 ms a tick; target <= 50 ms")
    # the corridor fit's laws, with the parameters their study flew (studies/corridor_fit.yaml)
    study = yaml.safe_load((ROOT / "studies" / "corridor_fit.yaml").read_text())
    for law in ("gov_fit", "gov_hold"):
        row(f"{law} tick (CPU, studies/corridor_fit.yaml)",
            pair_tick_times(20 * args.repeats, make_gov_law,
                            study["controllers"][law]["params"]),
            target="   budget 16 ms a tick; target <= 50 ms")
    unwind = yaml.safe_load((ROOT / "studies" / "unwind.yaml").read_text())
    row("gov_uw tick (CPU, studies/unwind.yaml)",
        pair_tick_times(20 * args.repeats, make_gov_law, unwind["controllers"]["gov_uw"]["params"]),
        target="   budget 16 ms a tick; target <= 50 ms")
    ours, ref = allocation_times(20 * args.repeats)
    row("allocation, active set (CPU)", ours, "us")
    row("allocation, scipy lsq_linear bvls (CPU)", ref, "us")


if __name__ == "__main__":
    main()
