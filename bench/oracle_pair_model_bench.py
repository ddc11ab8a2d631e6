"""Speed of the pair model with the swing (astrobee_control.pair_model) in batched numpy rollouts.

    python bench/oracle_pair_model_bench.py

Prints the time of one RK4 step for N = 1, 128 and 1024 states and of a 5 s rollout (62.5 Hz)
of 128 candidates. Reference (this machine, 2026-11-26): at load ~3, one step of 1000 states
12 ms and of one state 0.94 ms; at load ~11, N=1 7.7 ms, N=128 16 ms, N=1024 52 ms, the 5 s
rollout of 128 candidates 3.1 s (numpy's per-call overhead dominates small batches: batch).
"""
from __future__ import annotations

import time

import numpy as np

from astrobee_control import pair_model as pm


def main() -> None:
    p = pm.load("fem")
    x = pm.state(np.zeros(3), np.zeros(3), [0, 0, 0, 1], np.zeros(3), [0, 0, 0, 1], np.zeros(3))
    for n in (1, 128, 1024):
        xs = np.repeat(x[None], n, 0)
        pm.rk4(xs, np.zeros(6), None, p, 0.016)
        t = time.perf_counter()
        for _ in range(20):
            pm.rk4(xs, np.zeros(6), None, p, 0.016)
        print(f"N={n:5d}: one RK4 step {1e3 * (time.perf_counter() - t) / 20:.2f} ms")
    us = np.random.default_rng(0).uniform(-0.3, 0.3, (128, 312, 6))
    t = time.perf_counter()
    pm.rollout(np.repeat(x[None], 128, 0), us, 0.016, p)
    print(f"128 candidates x 5 s at 62.5 Hz: {time.perf_counter() - t:.2f} s")


if __name__ == "__main__":
    main()
