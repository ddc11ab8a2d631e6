"""MPC decision time per replan: rollout model A (reduced, one core), the attitude-aware mode
on it (`attitude: true`: per-candidate attitude references, time scaling, attitude cost; timed
on a pair turned 0.3 rad and turning at 0.1 rad/s), and model B (pybullet worker processes),
N samples x 5 s horizon, robot + 10 kg bag in Node 2.

    .venv/bin/python bench/mpc_bench.py [--samples 128] [--repeats 40] [--b-samples 32] [--no-b]
"""
from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")   # one core for model A

import numpy as np  # noqa: E402

from astrobee import flight_modes  # noqa: E402
from astrobee import rotations as rot  # noqa: E402
from astrobee_control import mass as mp  # noqa: E402
from astrobee_control.handle_models import HandleParams, identified_handles  # noqa: E402
from astrobee_control.law import BagObservation  # noqa: E402
from astrobee_control.mpc import MpcConfig, MpcLaw  # noqa: E402
from astrobee_control.pd import State  # noqa: E402
from astrobee_control.reduced_model import ReducedModel  # noqa: E402
from astrobee_control.reference import rest_to_rest  # noqa: E402

Q = np.array([0.0, 0.0, -0.7071067811865476, 0.7071067811865476])


def timed(law: MpcLaw, repeats: int, spun: bool = False) -> np.ndarray:
    p0 = np.array([10.95, 0.0, 4.84])
    law.follow(rest_to_rest(p0, p0 + [0.0, -2.0, 0.0], Q, Q, 30.0), 0.0)
    rng = np.random.default_rng(0)
    q = rot.multiply(Q, rot.from_rotvec(np.array([0.0, 0.3, 0.0]))) if spun else Q
    w = np.array([0.0, 0.1, 0.0]) if spun else np.zeros(3)
    out = []
    for i in range(repeats):
        st = State(p0 + rng.normal(0, 0.02, 3), rng.normal(0, 0.01, 3), q, w)
        d = np.array([-0.477, 0.0, -0.047])
        bag = BagObservation(st.position + rot.rotate(q, d), q, rng.normal(0, 0.01, 3),
                             np.zeros(3), True, 10.0, np.array([0.5, 0.42, 0.25]), "fem")
        law.observe_bag(bag, st)
        t, c = time.perf_counter(), time.process_time()
        law.decide(st, 0.5 * i)
        out.append((time.perf_counter() - t, time.process_time() - c))
    return 1e3 * np.array(out)   # (repeats, 2): wall, CPU of this process


def row(name: str, ms: np.ndarray, target: str) -> None:
    """Wall median/p99, and the CPU median (what a shared, loaded machine leaves comparable)."""
    w, c = ms[:, 0], ms[:, 1]
    print(f"{name:44s} median {np.median(w):8.1f} ms   p99 {np.percentile(w, 99):8.1f} ms   "
          f"(CPU median {np.median(c):6.1f} ms, p99 {np.percentile(c, 99):6.1f} ms)   {target}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--samples", type=int, default=128)
    ap.add_argument("--repeats", type=int, default=40)
    ap.add_argument("--b-samples", type=int, default=32)
    ap.add_argument("--no-b", action="store_true", help="skip model B (pybullet workers)")
    a = ap.parse_args()
    fm, m = flight_modes.get("nominal"), mp.robot()
    handle = identified_handles().get("fem") or HandleParams([30, 1e5, 1.5], [20, 0.01, 1], 0)
    cfg = MpcConfig(samples=a.samples, horizon=5.0)
    print(f"MPC decision time per replan, {a.samples} samples x 5 s horizon "
          f"(rollout step {cfg.rollout_dt} s), robot + 10 kg bag")
    law = MpcLaw(fm, m, ReducedModel(handle), cfg)
    timed(law, 3)
    row(f"model A ({getattr(handle, 'kind', 'spring')}, numpy, one core), N={a.samples}",
        timed(law, a.repeats), "target <= 50 ms; pyastrobee: not real time on 16 cores")
    if not isinstance(handle, HandleParams):   # the attitude-aware mode (turning model only)
        law_t = MpcLaw(fm, m, ReducedModel(handle), MpcConfig(samples=a.samples, horizon=5.0,
                                                              attitude=True))
        timed(law_t, 3, spun=True)
        row(f"model A, attitude-aware (spun pair), N={a.samples}",
            timed(law_t, a.repeats, spun=True), "vs the translation-only row above")
    if not isinstance(handle, HandleParams):   # the previous model A, same load, for scale
        spring = HandleParams([30, 1e5, 1.5], [20, 0.01, 1], [-0.477, 0.0, -0.047])
        law_s = MpcLaw(fm, m, ReducedModel(spring), cfg)
        timed(law_s, 3)
        row(f"model A (spring point mass, previous), N={a.samples}", timed(law_s, a.repeats), "")
    if a.no_b:
        return
    from astrobee_control.rollout_pybullet import PybulletModel
    for bag in ("constraint",):
        model = PybulletModel(workers=2, bag_model=bag)
        try:
            law_b = MpcLaw(fm, m, model, MpcConfig(samples=a.b_samples, horizon=5.0))
            timed(law_b, 1)
            ms = timed(law_b, max(3, a.repeats // 8))
            row(f"model B (pybullet {bag}, 2 workers), N={a.b_samples}", ms,
                f"(x{a.samples / a.b_samples:.0f} for N={a.samples}: ~{np.median(ms[:, 0]) * a.samples / a.b_samples / 1e3:.1f} s)")
        finally:
            model.close()


if __name__ == "__main__":
    main()
