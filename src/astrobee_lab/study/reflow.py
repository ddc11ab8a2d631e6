"""Spot check of a study: one row re-flown through the whole graph (`astrobee launch
cargo_transport`: router, sim_node in lockstep, planner_node, the controller node, recorder,
mission) with the same scenario, overrides, realism knobs, controller parameters, safety
filter and seed, and its summary compared with the row.

The flight's scenario (overrides and realism applied) and the controller's parameters go into
a copy of config/ (ASTROBEE_CONFIG_DIR) as scenarios/study_<key>.yaml and controllers.yaml, so
any row can be re-flown, knobs and inline scenarios included, without new launch arguments
beyond `seed`. Flights through the graph are not bit-identical to in-process ones (message
timing: the bag's state reaches the controller through the router), so the comparison uses
tolerances (TOLERANCES) and the verdict must agree.
"""
from __future__ import annotations

import json
import math
import os
import shutil
import socket
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .spec import StudyError, build_scenario, load_study, task_keywords

# metric -> (absolute tolerance, relative tolerance): |graph - row| <= abs + rel * |row|
TOLERANCES = {
    "final_position_error": (0.02, 0.5),
    "final_attitude_error": (0.05, 0.5),
    "rms_position_error": (0.005, 0.5),
    "min_robot_clearance": (0.02, 0.0),
    "min_bag_clearance": (0.03, 0.0),
    "contacts": (3, 0.5),
}


@dataclass
class ReflowResult:
    """The row, the graph's leg summary and how they compare."""

    key: str
    row: dict
    leg: dict
    run_dir: Path
    checks: dict[str, tuple[Any, Any, bool]] = field(default_factory=dict)
    launch_rc: int = 0

    @property
    def agrees(self) -> bool:
        return all(ok for _, _, ok in self.checks.values())

    def text(self) -> str:
        lines = [f"reflow of {self.key} through the graph: {self.run_dir} (launch exit {self.launch_rc})"]
        for name, (a, b, ok) in self.checks.items():
            lines.append(f"  {'ok  ' if ok else 'DIFF'} {name:22s} study {_show(a):>12s}  graph {_show(b):>12s}")
        lines.append(f"  study: {self.row.get('cause')}")
        lines.append(f"  graph: {self.leg.get('reason')}")
        lines.append("agrees" if self.agrees else "DIFFERS")
        return "\n".join(lines)


def _show(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4f}"
    return str(v)


def _num(v: Any) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def compare(row: dict, leg: dict, recorded: dict | None = None) -> dict[str, tuple[Any, Any, bool]]:
    """The verdict equal to the mission's (summary.json) and, with `recorded` (the Task's
    judgement of the recording: success + metrics), to the Task's; each metric of TOLERANCES
    within its tolerance of the recording's (of the summary's without one; both nan: equal)."""
    out: dict[str, tuple[Any, Any, bool]] = {}
    out["success (mission)"] = (bool(row.get("success")), bool(leg.get("success")),
                                bool(row.get("success")) == bool(leg.get("success")))
    if recorded is not None:
        out["success (task)"] = (bool(row.get("success")), bool(recorded.get("success")),
                                 bool(row.get("success")) == bool(recorded.get("success")))
        leg = recorded
    for name, (a_tol, r_tol) in TOLERANCES.items():
        a, b = _num(row.get(name)), _num(leg.get(name))
        if math.isnan(a) and math.isnan(b):
            ok = True
        elif math.isnan(a) or math.isnan(b):
            ok = False
        else:
            ok = abs(a - b) <= a_tol + r_tol * abs(a)
        if name == "contacts":
            ok = ok and ((a > 0) == (b > 0))
        out[name] = (a, b, ok)
    return out


def judge_recording(spec: dict, leg: dict, bag: Path) -> dict | None:
    """The Task's verdict and metrics of the graph flight, read back from its recording (the
    in-process row's own judge; the mission's summary computes some figures its own way, e.g.
    its RMS error). None without a recording."""
    if not bag.is_dir():
        return None
    from astrobee.task import Task
    from ..recorded import judge_bag
    sc = build_scenario(spec)
    pd = leg.get("plan_duration")
    kw = task_keywords(spec)
    task = Task.from_scenario(sc, plan_duration=float(pd) if pd else None, **kw)
    m = judge_bag(bag, task)
    ok, cause = m.verdict()
    return {"success": ok, "cause": cause, **m.metrics()}


def find_row(folder: Path, which: str) -> tuple[Any, dict, dict]:
    """(FlightSpec, row, record) of a study folder's row: an index of results.csv / the study's
    order, or a flight key (a unique prefix)."""
    from .run import StudyStore
    if not (folder / "study.yaml").is_file():
        raise StudyError(f"{folder} is not a study folder (no study.yaml)")
    study = load_study(folder / "study.yaml")
    store = StudyStore(folder)
    done = store.done()
    if which.isdigit():
        i = int(which)
        if i >= len(study.flights):
            raise StudyError(f"row {i} is not in the study ({len(study.flights)} rows)")
        f = study.flights[i]
    else:
        hits = [f for f in study.unique.values() if f.key.startswith(which)]
        if len(hits) != 1:
            raise StudyError(f"{'no' if not hits else 'more than one'} flight key starts with {which!r}")
        f = hits[0]
    rec = done.get(f.key)
    if rec is None:
        raise StudyError(f"row {which} ({f.key}) has not been flown yet")
    from .run import make_row
    return f, make_row(f, rec), rec


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def prepare_config(spec: dict, key: str, into: Path) -> str:
    """A copy of config/ holding the flight's scenario and controller parameters; returns the
    scenario's name there."""
    from astrobee import config
    cfg = into / "config"
    shutil.copytree(config.config_dir(), cfg)
    sc = build_scenario(spec)
    name = f"study_{key}"
    data = sc.as_dict()
    data.pop("name", None)
    (cfg / "scenarios" / f"{name}.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    ctl_path = cfg / "controllers.yaml"
    ctl = yaml.safe_load(ctl_path.read_text()) or {}
    section = dict(ctl.get(spec["controller"]) or {})
    section.update(spec.get("params") or {})
    ctl[spec["controller"]] = section
    ctl_path.write_text(yaml.safe_dump(ctl, sort_keys=False))
    return name


def launch_command(spec: dict, scenario: str, run_dir: Path, port: int,
                   video: bool = False) -> list[str]:
    """The `astrobee launch cargo_transport` line that flies a spec through the graph."""
    return [sys.executable, "-m", "astrobee_bringup.cli", "launch", "cargo_transport",
            f"scenario:={scenario}", f"controller:={spec['controller']}",
            f"safety:={'true' if spec['safety'] else 'false'}", f"seed:={int(spec['seed'])}",
            f"video:={'true' if video else 'false'}", "--run-dir", str(run_dir),
            "--port", str(port)]


def reflow(folder: str | Path, which: str, *, port: int = 0, timeout: float = 900.0,
           video: bool = False, run_dir: str | Path | None = None) -> ReflowResult:
    """Re-fly one row of a study folder through the graph and compare (see the module doc)."""
    folder = Path(folder)
    f, row, rec = find_row(folder, which)
    spec = f.spec
    if spec.get("state_source", "ekf") != "ekf":
        raise StudyError("reflow flies the graph's controller on /gnc/ekf: a row with "
                         f"state_source {spec['state_source']!r} cannot be re-flown")
    run_dir = Path(run_dir) if run_dir else folder / "reflow" / f.key
    if run_dir.exists():
        shutil.rmtree(run_dir)
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="reflow_") as tmp:
        scenario = prepare_config(spec, f.key, Path(tmp))
        env = dict(os.environ, ASTROBEE_CONFIG_DIR=str(Path(tmp) / "config"))
        cmd = launch_command(spec, scenario, run_dir, port or _free_port(), video)
        try:
            proc = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                  text=True, timeout=timeout, start_new_session=True)
            rc, out = proc.returncode, proc.stdout
        except subprocess.TimeoutExpired as exc:
            raise StudyError(f"the launch took longer than {timeout:g} s (see {run_dir})") from exc
    (run_dir.mkdir(parents=True, exist_ok=True))
    (run_dir / "launch.log").write_text(out)
    summary = run_dir / "summary.json"
    if not summary.is_file():
        last = out.strip().splitlines()[-1] if out.strip() else "no output"
        raise StudyError(f"the launch wrote no summary.json (exit {rc}): {last}")
    data = json.loads(summary.read_text())
    legs = data.get("legs") or []
    if not legs:
        raise StudyError(f"{summary} has no leg: {data.get('cause', '')}")
    leg = legs[0]
    recorded = judge_recording(spec, leg, run_dir / "bag")
    res = ReflowResult(f.key, row, leg, run_dir, compare(row, leg, recorded), rc)
    (run_dir / "reflow.json").write_text(json.dumps(
        {"key": f.key, "agrees": res.agrees, "tolerances": TOLERANCES,
         "checks": {k: [a, b, ok] for k, (a, b, ok) in res.checks.items()},
         "row_cause": row.get("cause"), "graph_reason": leg.get("reason")}, indent=1, default=str))
    return res
