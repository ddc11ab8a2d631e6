"""Study runner throughput: flights per hour serially vs on the local process pool (target
>= 1.8x on 2 cores) and, when ray is importable, the scheduling overhead per flight on a local
Ray (target <= 5% of a flight).

The study: PD carrying the rigid bag Node 2 -> JEM (44 s of sim), astrobee realism, N seeds.
Overhead per flight = (workers x elapsed - sum of the flights' own wall times) / flights,
against the mean flight: what the backend adds (process start, imports, scheduling, result
transfer, the atomic row writes).

Usage: python bench/study_bench.py [--flights 12] [--workers 2]
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path


def study_file(folder: Path, flights: int) -> Path:
    import yaml
    p = folder / "bench.yaml"
    p.write_text(yaml.safe_dump({
        "name": "bench", "controllers": {"pd": {"controller": "pd"}},
        "base": {"scenario": "node2_to_jem_bag", "realism": "astrobee"},
        "seeds": flights, "grid": {"controller": ["pd"]}}))
    return p


def measure(path: Path, out: Path, **kw) -> tuple[float, list[dict]]:
    from astrobee_lab.study.run import read_table, run_study
    if out.exists():
        shutil.rmtree(out)
    t0 = time.perf_counter()
    run = run_study(path, out, progress=False, report=False, **kw)
    elapsed = time.perf_counter() - t0
    return elapsed, read_table(run.table)


def line(name: str, elapsed: float, rows: list[dict], workers: int) -> dict:
    n = len(rows)
    own = sum(float(r["wall_time"]) for r in rows)
    over = (workers * elapsed - own) / n
    mean = own / n
    print(f"{name:8s} {n:3d} flights {elapsed:7.1f} s  {3600 * n / elapsed:7.0f} flights/h  "
          f"mean flight {mean:5.1f} s  overhead/flight {over:5.2f} s ({100 * over / mean:4.1f}%)")
    return {"elapsed": elapsed, "per_hour": 3600 * n / elapsed, "overhead": over / mean}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--flights", type=int, default=12)
    p.add_argument("--workers", type=int, default=2)
    a = p.parse_args(argv)
    load = os.getloadavg()[0]
    print(f"study runner: {a.flights} flights (PD, rigid bag, Node 2 -> JEM, astrobee realism); "
          f"{os.cpu_count()} cores, load {load:.1f} at the start")
    with tempfile.TemporaryDirectory(prefix="study_bench_") as tmp:
        tmp = Path(tmp)
        path = study_file(tmp, a.flights)
        serial = line("serial", *measure(path, tmp / "serial", workers=1), 1)
        pool = line(f"pool({a.workers})", *measure(path, tmp / "pool", workers=a.workers), a.workers)
        print(f"pool / serial: {pool['per_hour'] / serial['per_hour']:.2f}x flights per hour "
              f"(target >= 1.8x on 2 cores)")
        try:
            import ray
        except ImportError:
            print("ray: not installed (pip install '.[ray]'): Ray overhead not measured")
            return 0
        ray.init(num_cpus=a.workers, include_dashboard=False, log_to_driver=False)
        try:
            r = line(f"ray({a.workers})", *measure(path, tmp / "ray", ray="local"), a.workers)
        finally:
            ray.shutdown()
        print(f"ray scheduling overhead: {100 * r['overhead']:.1f}% of a flight (target <= 5%; "
              "the first Ray task also starts its worker processes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
