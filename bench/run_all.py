"""Run every benchmark in bench/ (each prints its own table beside the reference figures).

Usage: python bench/run_all.py
Each benchmark runs in its own process so one failing or slow bench does not stop the rest.
"""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path


# not benchmarks: train_residual.py trains a policy for minutes (optional [rl] extra)
SKIP = {"run_all.py", "train_residual.py"}


def main() -> int:
    here = Path(__file__).resolve().parent
    failed = []
    for script in sorted(here.glob("*.py")):
        if script.name in SKIP or script.name.startswith("_"):
            continue
        print(f"\n=== {script.name} ===", flush=True)
        t0 = time.monotonic()
        rc = subprocess.call([sys.executable, str(script)], cwd=here.parent)
        print(f"--- {script.name}: exit {rc}, {time.monotonic() - t0:.1f} s", flush=True)
        if rc != 0:
            failed.append(script.name)
    if failed:
        print(f"\nfailed benchmarks: {', '.join(failed)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
