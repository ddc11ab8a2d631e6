"""Start-up time of the command verbs: from exec to the first message (`topic echo --once`)
or to the full answer (`topic list`, `node list`, `service call`), beside `ros2`'s usual ~1 s.

    .venv/bin/python bench/cli_startup.py [--quick | --full]
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ASTROBEE = str(Path(sys.executable).parent / "astrobee")
ADDER = str(Path(__file__).resolve().parents[1] / "tests" / "cli" / "adder_node.py")
REFERENCE = {  # typical ros2 (Jazzy, rmw_zenoh, no daemon running) wall times, seconds
    "topic echo --once (first message)": "~1.0",
    "topic list": "~0.8",
    "node list": "~0.8",
    "service call (AddTwoInts)": "~1.0",
    "interface show PoseStamped": "~0.5",
}


def timed(argv, env, expect: str) -> tuple[float, float]:
    """(wall s, CPU s of the command): CPU time does not grow when other jobs load the box."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.monotonic()
    p = subprocess.run([ASTROBEE, *argv], env=env, capture_output=True, text=True, timeout=60)
    dt = time.monotonic() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    if p.returncode != 0 or expect not in p.stdout:
        raise RuntimeError(f"{argv}: rc={p.returncode} out={p.stdout[-300:]} err={p.stderr[-300:]}")
    return dt, cpu


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--quick", action="store_true", help="5 runs each (default)")
    g.add_argument("--full", action="store_true", help="20 runs each")
    a = ap.parse_args()
    runs = 20 if a.full else 5
    from roszen import testing
    cases = {
        "topic echo --once (first message)": (["topic", "echo", "/adder/count", "--once"],
                                              "data:"),
        "topic list": (["topic", "list"], "/adder/count"),
        "node list": (["node", "list"], "/adder"),
        "service call (AddTwoInts)": (["service", "call", "/add_two_ints",
                                       "example_interfaces/srv/AddTwoInts", "{a: 1, b: 2}"],
                                      "sum=3"),
        "interface show PoseStamped": (["interface", "show", "geometry_msgs/msg/PoseStamped"],
                                       "frame_id"),
    }
    results = {}
    with testing.router() as port:
        env = testing.zenoh_env(port)
        adder = testing.spawn([sys.executable, ADDER], env)
        try:
            testing.read_until(adder, "adder ready", timeout=20)
            for name, (argv, expect) in cases.items():
                timed(argv, env, expect)          # warm the file cache
                results[name] = [timed(argv, env, expect) for _ in range(runs)]
        finally:
            testing.stop(adder)
    print(f"\ncommand start-up, exec to answer ({runs} runs; router + a 10 Hz publisher "
          "running; 2-core machine)")
    print(f"load average at the end: {os.getloadavg()[0]:.1f}")
    head = (f"{'command':36} {'median s':>9} {'min s':>7} {'max s':>7} {'cpu s':>7} "
            f"{'ros2 s':>7}")
    print(head)
    print("-" * len(head))
    for name, ts in results.items():
        wall = [w for w, _ in ts]
        cpu = statistics.median(c for _, c in ts)
        print(f"{name:36} {statistics.median(wall):9.3f} {min(wall):7.3f} {max(wall):7.3f} "
              f"{cpu:7.3f} {REFERENCE[name]:>7}")
    print("echo at 10 Hz waits up to 0.1 s for the next message after subscribing")
    return 0


if __name__ == "__main__":
    sys.exit(main())
