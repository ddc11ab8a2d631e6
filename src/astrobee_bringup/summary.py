"""Run summary: the verdict of a run (a leg's is astrobee.task's, judged by the mission on the
leg's samples: astrobee_bringup.mission.result), summary.json, and `finalize` (the plots
re-drawn from the closed recording).

The pieces it used to hold live in modules of one job: the flight's time series and reading it
back from the recording in astrobee_bringup.series, the leg's plot in astrobee_bringup.leg_plot.
Wording: "cargo bag" is the carried bag; "recording"
is the rosbag2 directory of the run.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from astrobee.task import robot_named
from astrobee_bringup.leg_plot import plot
from astrobee_bringup.series import read_bag


@dataclass
class RobotResult:
    """One robot's part of a leg (summary.json's legs[i].robots[j])."""

    name: str                                   # namespace ("" = the default robot)
    success: bool = False
    reason: str = ""
    reached_goal: bool = False
    start: list[float] = field(default_factory=list)
    goal: list[float] = field(default_factory=list)        # position + quaternion
    final_position_error: float | None = None
    final_attitude_error: float | None = None
    rms_position_error: float | None = None
    max_position_error: float | None = None
    max_attitude_error: float | None = None
    min_clearance: float | None = None          # m, envelope to the keep-in boundary
    contacts: int = 0                           # samples with this robot touching the station
    faults: list[str] = field(default_factory=list)
    failed_at: dict[str, Any] | None = None     # {"t": sim s, "position": [x, y, z], "why": ...}


def run_verdict(legs: list[dict[str, Any]]) -> tuple[bool, str]:
    """A run succeeds only if every leg did; any fault of any robot in any leg fails it, the
    robot named. Returns (success, reason: the failing legs' reasons)."""
    bad = []
    for leg in legs:
        faults = [f"{robot_named(r['name'])}: {f}" for r in leg.get("robots", [])
                  for f in r.get("faults", [])]
        if not leg.get("success") or faults:
            why = leg.get("reason", "") or "; ".join(faults)
            if faults and not any(robot_named(r["name"]) in why for r in leg.get("robots", [])
                                  if r.get("faults")):
                why += " (faults: " + "; ".join(faults) + ")"
            bad.append(f"{leg.get('scenario', '?')}: {why}")
    ok = bool(legs) and not bad
    return ok, "every leg reached its goal" if ok else "; ".join(bad) or "no leg flown"


def write_json(path: str | os.PathLike, data: dict[str, Any]) -> None:
    """Write summary.json atomically (a reader never sees half a file)."""
    path = Path(path)
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(_jsonable(data), indent=2) + "\n")
    os.replace(tmp, path)


def _jsonable(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, set)):
        return [_jsonable(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return float(v) if math.isfinite(float(v)) else None
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.ndarray):
        return _jsonable(v.tolist())
    return v


def finalize(run_dir: str | os.PathLike, bag_dir: str | os.PathLike) -> str:
    """After the graph stopped: re-draw each leg's plot from the closed recording (every robot
    of the leg) and note the recording's figures in summary.json. Returns a one-line report."""
    from astrobee import config

    run_dir, bag_dir = Path(run_dir), Path(bag_dir)
    path = run_dir / "summary.json"
    if not path.exists():
        return f"[summary] no {path}: the mission did not report"
    data = json.loads(path.read_text())
    if not bag_dir.exists():
        data["recording"] = {"path": str(bag_dir), "error": "nothing recorded"}
        write_json(path, data)
        return f"[summary] {path} (no recording at {bag_dir})"
    legs = data.get("legs", [])
    try:
        series = read_bag(bag_dir)
        parts = []
        for leg in legs:
            if leg.get("wall_t0") is None or leg.get("wall_t1") is None:
                parts.append(None)
                continue
            names = [r.get("name", "") for r in leg.get("robots", [])] or [""]
            parts.append({n: read_bag(bag_dir, n, log_window=(leg["wall_t0"], leg["wall_t1"]))
                          for n in names})
    except Exception as exc:  # noqa: BLE001 - an unreadable recording is reported, not fatal
        data["recording"] = {"path": str(bag_dir), "error": str(exc)}
        write_json(path, data)
        return f"[summary] {path} (recording unreadable: {exc})"
    boxes = config.keep_in_boxes()
    for leg, part in zip(legs, parts):
        if part is None or not any(s.position for s in part.values()):
            continue
        name = "plot.png" if len(legs) == 1 else f"plot_{leg['scenario']}.png"
        verdict = "SUCCESS" if leg.get("success") else "FAILED"
        plot(part, run_dir / name, boxes,
             title=f"{leg['scenario']}: {verdict}: {leg.get('reason', '')} (from the recording)",
             start=leg["start"][:3] if leg.get("start") else None,
             goal=leg["goal"][:3] if leg.get("goal") else None,
             robots=leg.get("robots") or None, t0=leg.get("sim_t0"), success=bool(leg.get("success")))
        leg["plot"] = name
        leg["plot_source"] = "recording"
        for r in leg.get("robots", []):
            s = part.get(r.get("name", ""))
            if s is not None:
                r["recording_rms_position_error"] = s.tracking()["rms_position_error"]
        leg["recording_rms_position_error"] = next(iter(part.values())).tracking()["rms_position_error"]
    data["recording"] = {"path": str(bag_dir), "pose_samples": len(series.pose_t),
                         "command_samples": len(series.err_t), "contact_samples": len(series.clear_t)}
    if len(legs) == 1:
        data["plot"] = legs[0].get("plot", data.get("plot", ""))
    write_json(path, data)
    return (f"[summary] {path}: {'SUCCESS' if data.get('success') else 'FAILED'}; plots from the "
            f"recording {bag_dir} ({len(series.pose_t)} poses)")
