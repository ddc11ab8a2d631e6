"""`astrobee study`: run a study file, rebuild its report, re-fly one of its rows through the
graph.

    astrobee study run studies/smoke.yaml [--workers N | --ray auto|local|ADDRESS] [--out DIR]
                                          [--only controller=pd,wmpc --only seed=0,1 ...]
    astrobee study report runs/study_smoke            # report.md, report.html, plots/ [--only ...]
    astrobee study reflow runs/study_smoke ROW        # ROW: index in results.csv or a key prefix
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from .spec import StudyError


def _run(a: argparse.Namespace) -> int:
    from .run import run_study
    from .spec import load_study
    from .subset import parse_only, select
    study = select(load_study(a.file), parse_only(a.only or []))
    if a.list:
        for f in study.flights:
            print(f"{f.index:4d} {f.key} {f.block:12s} {f.label:10s} seed={f.spec['seed']} "
                  + " ".join(f"{k}={v}" for k, v in f.swept.items()))
        print(f"{len(study.flights)} rows, {len(study.unique)} flights")
        return 0
    run = run_study(study, a.out, workers=a.workers, ray=a.ray, progress=not a.quiet,
                    limit=a.limit)
    print(f"[study] {run.flown} flown, {run.resumed} resumed, {run.errors} errors; "
          f"table {run.table}" + (f", report {run.report}" if run.report else ""))
    return 0


def _report(a: argparse.Namespace) -> int:
    from .run import StudyStore
    from .report import write_report
    from .spec import load_study
    folder = Path(a.dir)
    if not (folder / "study.yaml").is_file():
        raise StudyError(f"{folder} is not a study folder (no study.yaml)")
    from .subset import parse_only, select
    study = select(load_study(folder / "study.yaml"), parse_only(a.only or []))
    store = StudyStore(folder)
    table = store.write_table(study)
    md = write_report(study, store.table(study), folder)
    print(f"{md}, {md.with_name('report.html')} ({table})")
    return 0


def _reflow(a: argparse.Namespace) -> int:
    from .reflow import reflow
    result = reflow(a.dir, a.row, port=a.port, timeout=a.timeout, video=a.video)
    print(result.text())
    return 0 if result.agrees else 3


def main(argv: list[str] | None = None) -> int:
    """Entry of `astrobee study` (exit 1 with one line for a bad study or argument)."""
    p = argparse.ArgumentParser(prog="astrobee study", description="Monte Carlo studies of "
                                "cargo-transport flights (in-process, pool or Ray).")
    sub = p.add_subparsers(dest="verb", required=True)
    r = sub.add_parser("run", help="fly every flight of a study file not yet done")
    r.add_argument("file", help="study YAML (see studies/)")
    r.add_argument("--out", help="study folder (default runs/study_<name>)")
    r.add_argument("--workers", "-j", type=int, default=None,
                   help="local processes (default: every core; 1: in this process)")
    r.add_argument("--ray", metavar="ADDRESS", help="run on Ray: auto (the running cluster), "
                   "local (start one here) or host:port")
    r.add_argument("--limit", type=int, help="fly at most this many new flights")
    r.add_argument("--only", action="append", metavar="KEY=V1,V2",
                   help="fly only the flights whose controller label, block, seed or swept "
                   "parameter has one of these values (repeatable; the same flight keys, so the "
                   "whole study resumes from them)")
    r.add_argument("--list", action="store_true", help="list the flights and exit")
    r.add_argument("--quiet", "-q", action="store_true", help="no progress line")
    r.set_defaults(func=_run)
    rp = sub.add_parser("report", help="rewrite results.csv, report.md, report.html (one "
                        "self-contained page) and plots of a folder")
    rp.add_argument("dir")
    rp.add_argument("--only", action="append", metavar="KEY=V1,V2",
                    help="report only these flights (as `run --only`: a subset, said so)")
    rp.set_defaults(func=_report)
    rf = sub.add_parser("reflow", help="re-fly one row through the whole graph and compare")
    rf.add_argument("dir", help="study folder")
    rf.add_argument("row", help="row index in results.csv, or a flight key (prefix)")
    rf.add_argument("--port", type=int, default=0, help="router port (default: a free one)")
    rf.add_argument("--timeout", type=float, default=900.0, help="wall s for the launch")
    rf.add_argument("--video", action="store_true", help="also render the leg's MP4")
    rf.set_defaults(func=_reflow)
    a = p.parse_args(argv)
    if getattr(a, "workers", None) is not None and a.workers < 1:
        print(f"astrobee study: --workers must be >= 1, got {a.workers}", file=sys.stderr)
        return 1
    try:
        return a.func(a)
    except StudyError as exc:
        print(f"astrobee study: {exc}", file=sys.stderr)
        return 1
    except BrokenPipeError:            # `astrobee study run F --list | head`
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except KeyboardInterrupt:
        print("astrobee study: interrupted (finished flights are kept; run again to resume)",
              file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
