"""The study runner: every flight of a study file flown in-process (astrobee_lab.flight.Flight,
judged by astrobee.task, as the mission judges a leg), serially, on a local process pool or on
Ray, with resume, a progress line and a report.

    study = load_study("studies/controller_study.yaml")
    run_study(study, "runs/study_controller_study", workers=2)      # or ray="auto"

The study folder holds `study.yaml` (the file as run), `flights/<key>.json` (one per flight:
spec, row, status; written atomically by the driver when the flight ends: a killed study
resumes from them and never flies a finished flight twice), `results.csv` (+ .parquet with
pyarrow: one row per flight of the study, in the study's order), `report.md` and `plots/`.
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
import signal
import socket
import sys
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

from .spec import OVERRIDES, FlightSpec, Study, StudyError, build_scenario, load_study, task_keywords

# columns of the table that measure the machine, not the flight (differ run to run)
COST_COLUMNS = ("wall_time", "real_time_factor", "compute_ms_median", "compute_ms_p99",
                "planning_time")
STUDY_COLUMNS = ("index", "key", "block", "label")


def fly(spec: dict) -> dict:
    """Fly one flight of a study (its spec) and return its record: row, status, host. Errors
    in the flight are recorded (status 'error'), not raised, so that one bad flight does not
    stop a study."""
    from ..flight import Flight
    t0 = time.perf_counter()
    record: dict[str, Any] = {"spec": spec, "host": socket.gethostname(), "pid": os.getpid()}
    try:
        scenario = build_scenario(spec)
        task = task_keywords(spec) or None
        with Flight(scenario, seed=int(spec["seed"]), controller=spec["controller"],
                    safety=bool(spec["safety"]), controller_params=spec["params"],
                    state_source=spec.get("state_source", "ekf"), task=task) as f:
            res = f.run()
        row = res.row()
        record.update(status="ok", row={k: _cell(v) for k, v in row.items()})
    except Exception as exc:      # noqa: BLE001 - recorded with the flight, the study goes on
        sc = spec["scenario"]
        record.update(status="error", error=f"{type(exc).__name__}: {exc}",
                      row={"scenario": sc.get("name", "inline") if isinstance(sc, dict) else sc,
                           "safety": spec["safety"], "seed": spec["seed"], "success": False,
                           "cause": f"error: {type(exc).__name__}: {exc}",
                           "wall_time": time.perf_counter() - t0})
    record["finished_at"] = time.time()
    return record


def _cell(v: Any) -> Any:
    if hasattr(v, "item"):
        v = v.item()
    return v


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "w") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


class StudyStore:
    """A study folder: the finished flights (by key), the table and the copy of the study."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        self.flights_dir = self.folder / "flights"

    def prepare(self, study: Study) -> None:
        self.flights_dir.mkdir(parents=True, exist_ok=True)
        import yaml
        _write_atomic(self.folder / "study.yaml", yaml.safe_dump(study.source, sort_keys=False))

    def done(self, errors: bool = True) -> dict[str, dict]:
        """key -> record of every finished flight in the folder (unreadable files skipped;
        errors=False leaves out flights that ended in an error, to fly them again)."""
        out = {}
        if not self.flights_dir.is_dir():
            return out
        for p in sorted(self.flights_dir.glob("*.json")):
            try:
                rec = json.loads(p.read_text())
            except (OSError, ValueError):
                continue
            if errors or rec.get("status") != "error":
                out[p.stem] = rec
        return out

    def save(self, key: str, record: dict) -> None:
        record = {"key": key, **record}
        _write_atomic(self.flights_dir / f"{key}.json",
                      json.dumps(record, indent=1, default=_json_default, allow_nan=True))

    def table(self, study: Study, done: dict[str, dict] | None = None) -> list[dict]:
        """One row per flight of the study (in its order) that has finished."""
        done = self.done() if done is None else done
        rows = []
        for f in study.flights:
            rec = done.get(f.key)
            if rec is None:
                continue
            rows.append(make_row(f, rec, study.metrics))
        return rows

    def write_table(self, study: Study, done: dict[str, dict] | None = None) -> Path:
        rows = self.table(study, done)
        path = self.folder / "results.csv"
        _write_atomic(path, rows_to_csv(rows))
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:
            return path
        pq.write_table(pa.Table.from_pylist(rows), self.folder / "results.parquet")
        return path


def _json_default(v: Any) -> Any:
    if hasattr(v, "item"):
        return v.item()
    if hasattr(v, "tolist"):
        return v.tolist()
    return str(v)


def make_row(f: FlightSpec, record: dict, metrics: list[str] | None = None) -> dict:
    """The table row of a flight: study columns, swept values, then the flight's row (the
    controller column is the label; `law` the law it names)."""
    flown = dict(record.get("row") or {})
    row: dict[str, Any] = {"index": f.index, "key": f.key, "block": f.block, "label": f.label}
    row.update({k: _short(v) for k, v in f.swept.items()})
    setup_keys = ("scenario", *OVERRIDES, "safety", "realism", "state_source", "seed")
    kept = dict(flown)
    kept["law"] = f.spec["controller"]
    kept["controller"] = f.label
    kept["status"] = record.get("status", "ok")
    if metrics is not None:
        keep = set(setup_keys) | {"controller", "law", "status", "success", "cause"} | set(metrics)
        kept = {k: v for k, v in kept.items() if k in keep}
    for k, v in kept.items():
        row.setdefault(k, v)
    return row


def _short(v: Any) -> Any:
    return v if isinstance(v, (int, float, str, bool)) or v is None else json.dumps(v)


def rows_to_csv(rows: list[dict]) -> str:
    cols: list[str] = []
    for r in rows:
        cols += [c for c in r if c not in cols]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({c: _fmt(r.get(c, "")) for c in cols})
    return buf.getvalue()


def _fmt(v: Any) -> Any:
    if isinstance(v, float):
        return "nan" if math.isnan(v) else repr(v)
    return v


def read_table(path: str | Path) -> list[dict]:
    """results.csv back as rows (numbers parsed, 'True'/'False' as booleans)."""
    with open(path, newline="") as fh:
        return [{k: _parse(v) for k, v in r.items()} for r in csv.DictReader(fh)]


def _parse(v: str) -> Any:
    if v in ("True", "False"):
        return v == "True"
    try:
        return int(v)
    except ValueError:
        pass
    try:
        return float(v)
    except ValueError:
        return v


# ---- progress -----------------------------------------------------------------------------
class Progress:
    """One line per finished flight (or a rewritten line on a terminal): done/total, rate,
    ETA and the running success rate of every controller label."""

    def __init__(self, total: int, resumed: int, workers: int, stream=None,
                 enabled: bool = True) -> None:
        self.total, self.resumed, self.workers = total, resumed, workers
        self.done = resumed
        self.t0 = time.monotonic()
        self.new = 0
        self.ok: dict[str, list[int]] = defaultdict(lambda: [0, 0])
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def count(self, label: str, success: bool) -> None:
        self.ok[label][0] += bool(success)
        self.ok[label][1] += 1

    def flight_done(self, label: str, success: bool) -> None:
        self.done += 1
        self.new += 1
        self.count(label, success)
        if self.enabled:
            self.stream.write(("\r" if self.tty else "") + self.line() + ("" if self.tty else "\n"))
            self.stream.flush()

    def line(self) -> str:
        el = time.monotonic() - self.t0
        left = self.total - self.done
        eta = el / self.new * left if self.new else math.nan
        per_h = self.new / el * 3600 if el > 0 else 0.0
        rates = "  ".join(f"{k} {s}/{n}" for k, (s, n) in sorted(self.ok.items()))
        return (f"[study] {self.done}/{self.total} flights ({self.resumed} resumed) | "
                f"{per_h:.0f}/h | elapsed {_hms(el)} | ETA {_hms(eta)} | ok: {rates}")

    def close(self) -> None:
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()


def _hms(s: float) -> str:
    if not math.isfinite(s):
        return "--:--"
    s = int(round(s))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


# ---- backends -----------------------------------------------------------------------------
def _serial(todo: list[FlightSpec], on_done: Callable[[FlightSpec, dict], None]) -> None:
    for f in todo:
        on_done(f, fly(f.spec))


def _pool(todo: list[FlightSpec], workers: int, on_done: Callable[[FlightSpec, dict], None]) -> None:
    """A local process pool (spawned workers, reused across flights; the MPC's pybullet
    rollout workers may start their own processes inside them)."""
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    ex = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"))
    try:
        pending = {}
        queue = list(todo)
        # keep at most 2 flights per worker queued: a stop loses little, order stays close
        while queue or pending:
            while queue and len(pending) < 2 * workers:
                f = queue.pop(0)
                pending[ex.submit(fly, f.spec)] = f
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                f = pending.pop(fut)
                on_done(f, fut.result())
    finally:
        procs = list(getattr(ex, "_processes", {}).values())
        ex.shutdown(wait=False, cancel_futures=True)
        for p in procs:            # a stopped study does not leave flights running
            if p.is_alive():
                p.terminate()
        for p in procs:
            p.join(timeout=5)


def ray_init(address: str) -> Any:
    """ray.init for `--ray auto|local|ADDRESS` (StudyError when ray is not installed)."""
    try:
        import ray
    except ImportError:
        raise StudyError("--ray needs ray: pip install 'astrobee-cargo[ray]' (or pip install "
                         "ray)") from None
    if not ray.is_initialized():
        kw: dict[str, Any] = {"ignore_reinit_error": True, "log_to_driver": False,
                              "include_dashboard": False}
        if address == "local":
            ray.init(**kw)
        else:
            ray.init(address=address, **kw)
    return ray


def _ray(todo: list[FlightSpec], address: str, on_done: Callable[[FlightSpec, dict], None]) -> None:
    """Ray tasks (one CPU each) on the cluster at `address` ('auto': the running cluster;
    'local': a Ray started here). The package must be importable on every node."""
    ray = ray_init(address)
    remote = ray.remote(num_cpus=1, max_retries=1)(fly)
    pending = {remote.remote(f.spec): f for f in todo}
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        for ref in ready:
            f = pending.pop(ref)
            try:
                rec = ray.get(ref)
            except Exception as exc:      # noqa: BLE001 - a lost worker is recorded, not fatal
                rec = {"spec": f.spec, "status": "error", "error": f"ray: {exc}",
                       "row": {"success": False, "cause": f"error: ray: {exc}"}}
            on_done(f, rec)


@dataclass
class StudyRun:
    """What run_study did: folder, flights flown now, resumed, errors, the table path."""

    folder: Path
    flown: int
    resumed: int
    errors: int
    table: Path
    report: Path | None


def default_folder(study: Study) -> Path:
    return Path("runs") / f"study_{study.name}"


def run_study(study: Study | str | Path, folder: str | Path | None = None, *,
              workers: int | None = None, ray: str | None = None, progress: bool = True,
              report: bool = True, limit: int | None = None, stream=None) -> StudyRun:
    """Fly every flight of the study not yet in the folder; write the table (and the report).

    workers: 1 flies in this process; N > 1 a local pool of N (default: every core); ray: an
    address ('auto', 'local' or host:port) to run on Ray instead. limit: fly at most this
    many new flights (tests, benches)."""
    if not isinstance(study, Study):
        study = load_study(study)
    folder = Path(folder) if folder is not None else default_folder(study)
    store = StudyStore(folder)
    store.prepare(study)
    done = store.done(errors=False)      # a flight that ended in an error is flown again
    unique = study.unique
    # seed 0 of every flight first, then seed 1...: a stopped study covers every condition
    rank = {s: i for i, s in enumerate(dict.fromkeys(f.spec["seed"] for f in study.flights))}
    todo = sorted((f for k, f in unique.items() if k not in done),
                  key=lambda f: (rank[f.spec["seed"]], f.index))
    if limit is not None:
        todo = todo[:max(0, int(limit))]
    resumed = len(unique) - len([k for k in unique if k not in done])
    if workers is None:
        workers = os.cpu_count() or 1
    if workers < 1:
        raise StudyError(f"workers must be >= 1, got {workers}")
    prog = Progress(len(unique), resumed, workers, stream, progress)
    for k in unique:
        if k in done:
            prog.count(unique[k].label, bool((done[k].get("row") or {}).get("success")))
    errors = 0

    def on_done(f: FlightSpec, record: dict) -> None:
        nonlocal errors
        store.save(f.key, record)
        done[f.key] = {"key": f.key, **record}
        errors += record.get("status") == "error"
        prog.flight_done(f.label, bool((record.get("row") or {}).get("success")))

    if progress and stream is None:
        sys.stderr.write(f"[study] {study.name}: {len(unique)} flights ({len(study.flights)} rows), "
                         f"{resumed} already done, {len(todo)} to fly on "
                         f"{'ray ' + ray if ray else f'{min(workers, max(1, len(todo)))} worker(s)'}"
                         f" -> {folder}\n")
    stop = _raise_on_sigterm()
    try:
        if ray:
            _ray(todo, ray, on_done)
        elif workers == 1 or len(todo) <= 1:
            _serial(todo, on_done)
        else:
            _pool(todo, min(workers, len(todo)), on_done)
    finally:
        if stop is not None:
            signal.signal(signal.SIGTERM, stop)
        prog.close()
        table = store.write_table(study, done)
    rep = None
    if report:
        from .report import write_report
        rep = write_report(study, store.table(study, done), folder)
    return StudyRun(folder, len(todo), resumed, errors, table, rep)


def _raise_on_sigterm():
    """SIGTERM ends the runner as Ctrl-C does (the pool is stopped, the table written)."""
    def handler(signum, frame):
        raise KeyboardInterrupt
    try:
        return signal.signal(signal.SIGTERM, handler)
    except ValueError:            # not the main thread: leave the signals alone
        return None


def table_without_costs(rows: Iterable[dict]) -> list[dict]:
    """Rows without the columns that measure the machine (for comparing two runs); a NaN
    (a metric with no value) compares equal to a NaN."""
    def same(v):
        return "nan" if isinstance(v, float) and v != v else v
    return [{k: same(v) for k, v in r.items() if k not in COST_COLUMNS} for r in rows]
