"""astrobee.rotations per call: one quaternion (the scalar path in floats) vs the same call on a
batch of one (shape (1, 4): the array path, what one quaternion cost before the scalar paths),
in CPU microseconds (time.process_time, best of --repeat), and whether both give the same bits;
then the sim's numpy rigid backend (tests' backend: rotate, cross, step_body at 350 Hz), which
is made of such calls, in ticks per CPU second.

    .venv/bin/python bench/rotations_bench.py [--calls N] [--repeat R] [--ticks T]
"""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from astrobee import rotations as rot

Q = np.array([0.1, -0.2, 0.3, 0.9])
P = np.array([0.2, 0.1, -0.3, 0.8])
V = np.array([0.3, -1.0, 2.0])
# name, the call (given one quaternion or a batch of one)
WARM_UP = 100
CASES = [
    ("normalize", lambda q, p, v: rot.normalize(q)),
    ("multiply", lambda q, p, v: rot.multiply(q, p)),
    ("to_matrix", lambda q, p, v: rot.to_matrix(q)),
    ("rotate", lambda q, p, v: rot.rotate(q, v)),
    ("rotate_inverse", lambda q, p, v: rot.rotate_inverse(q, v)),
    ("to_rotvec", lambda q, p, v: rot.to_rotvec(q)),
    ("from_rotvec", lambda q, p, v: rot.from_rotvec(v)),
    ("attitude_error", lambda q, p, v: rot.attitude_error(q, p)),
]


def cpu_us(fn, calls: int, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        c0 = time.process_time()
        for _ in range(calls):
            fn()
        best = min(best, (time.process_time() - c0) / calls * 1e6)
    return best


def rigid_backend(ticks: int) -> float:
    """Ticks (6 physics steps each) per CPU s of the rigid backend with the bag, random wrenches."""
    from astrobee_sim.backend import make_backend
    sim = make_backend("rigid", "node2_to_jem_bag")
    try:
        rng = np.random.default_rng(1)
        scale = np.array([0.5, 0.5, 0.5, 0.05, 0.05, 0.05])
        c0 = 0.0
        for i in range(ticks + WARM_UP):
            if i == WARM_UP:                  # the first ticks pay one-time costs
                c0 = time.process_time()
            sim.command(rng.uniform(-1, 1, 6) * scale)
            sim.step(6)
            sim.robot_state()
            sim.bag_state()
            sim.clearance()
        return ticks / (time.process_time() - c0)
    finally:
        sim.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=5000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--ticks", type=int, default=2000, help="rigid backend ticks (0: skip)")
    a = ap.parse_args()
    q1, p1, v1 = Q[None], P[None], V[None]
    print(f"{'function':<16}{'one (scalar) us':>17}{'batch of one (array) us':>25}{'speed-up':>10}"
          f"{'same bits':>11}")
    for name, f in CASES:
        one = cpu_us(lambda: f(Q, P, V), a.calls, a.repeat)
        arr = cpu_us(lambda: f(q1, p1, v1), a.calls, a.repeat)
        same = np.array_equal(f(Q, P, V), f(q1, p1, v1)[0])
        print(f"{name:<16}{one:>17.2f}{arr:>25.2f}{arr / one:>9.1f}x{str(same):>11}")
    for name, f in [("angle_between", lambda: rot.angle_between(Q, P)),
                    ("slerp", lambda: rot.slerp(Q, P, 0.3)),
                    ("step_body", lambda: rot.step_body(rot.normalize(Q), V * 0.01))]:
        print(f"{name:<16}{cpu_us(f, a.calls, a.repeat):>17.2f}{'(no batch form)':>25}")
    print("reference: before the scalar paths one quaternion took the array path (the right "
          "column); an AstrobeeCargo-v0 step is ~400 us CPU (bench/gym_bench.py) and calls "
          "~17 of these")
    if a.ticks:
        print(f"\nrigid backend, node2_to_jem_bag, {a.ticks} ticks: "
              f"{rigid_backend(a.ticks):.0f} ticks per CPU s (reference: 1700-1880 with the "
              "array path, same loop, load 4-5)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
