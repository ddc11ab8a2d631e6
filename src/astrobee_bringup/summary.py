"""Run summary: time series of a flight (live or read back from the recorded bag), its figures
of merit, summary.json and the plot PNG (path over the keep-in boxes, tracking error, clearance).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np

# Topics a flight's figures come from (relative to the robot namespace; msgconv names them).
from astrobee.msgconv import COMMAND, MOB_STATE, POSE, TRAJ  # noqa: E402
CONTACTS = "sim/contacts"
BAG_STATE = "sim/bag/state"


def _t(stamp: Any) -> float:
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


@dataclass
class Series:
    """Time series of one flight (sim time, s). Each list grows as samples arrive."""

    pose_t: list[float] = field(default_factory=list)
    position: list[list[float]] = field(default_factory=list)
    orientation: list[list[float]] = field(default_factory=list)
    ref_t: list[float] = field(default_factory=list)
    ref_position: list[list[float]] = field(default_factory=list)
    err_t: list[float] = field(default_factory=list)
    pos_error: list[float] = field(default_factory=list)
    att_error: list[float] = field(default_factory=list)
    clear_t: list[float] = field(default_factory=list)
    robot_clearance: list[float] = field(default_factory=list)
    bag_clearance: list[float] = field(default_factory=list)
    in_contact: list[bool] = field(default_factory=list)
    contact_bodies: set[str] = field(default_factory=set)
    bag_t: list[float] = field(default_factory=list)
    bag_position: list[list[float]] = field(default_factory=list)
    controlling: list[tuple[float, float]] = field(default_factory=list)  # CONTROLLING spans

    # ---- feeding from messages (live subscriptions or a bag) -------------------------
    def add_pose(self, msg: Any) -> None:
        p, q = msg.pose.position, msg.pose.orientation
        self.pose_t.append(_t(msg.header.stamp))
        self.position.append([p.x, p.y, p.z])
        self.orientation.append([q.x, q.y, q.z, q.w])

    def add_command(self, msg: Any) -> None:
        e = msg.position_error
        if int(msg.control_mode) == 0:
            return  # idle: no reference, no tracking error
        self.err_t.append(_t(msg.header.stamp))
        self.pos_error.append(math.sqrt(e.x * e.x + e.y * e.y + e.z * e.z))
        self.att_error.append(float(msg.attitude_error_mag))

    def add_traj(self, msg: Any) -> None:
        p = msg.pose.position
        self.ref_t.append(_t(msg.when))
        self.ref_position.append([p.x, p.y, p.z])

    def add_contacts(self, msg: Any) -> None:
        self.clear_t.append(_t(msg.header.stamp))
        self.robot_clearance.append(float(msg.robot_clearance))
        self.bag_clearance.append(float(msg.bag_clearance))
        self.in_contact.append(bool(msg.in_contact))
        for c in msg.contacts:
            self.contact_bodies.add(f"{c.body_a}-{c.body_b}")

    def add_bag(self, msg: Any) -> None:
        p = msg.pose.position
        self.bag_t.append(_t(msg.header.stamp))
        self.bag_position.append([p.x, p.y, p.z])

    # ---- figures ----------------------------------------------------------------------
    def window(self, t0: float, t1: float) -> "Series":
        """The samples with t0 <= t <= t1 (one leg of a multi-leg run)."""
        out = Series(contact_bodies=set(self.contact_bodies))

        def cut(ts, *cols):
            idx = [i for i, t in enumerate(ts) if t0 <= t <= t1]
            return [[ts[i] for i in idx]] + [[c[i] for i in idx] for c in cols]

        out.pose_t, out.position, out.orientation = cut(self.pose_t, self.position, self.orientation)
        out.ref_t, out.ref_position = cut(self.ref_t, self.ref_position)
        out.err_t, out.pos_error, out.att_error = cut(self.err_t, self.pos_error, self.att_error)
        out.clear_t, out.robot_clearance, out.bag_clearance, out.in_contact = cut(
            self.clear_t, self.robot_clearance, self.bag_clearance, self.in_contact)
        out.bag_t, out.bag_position = cut(self.bag_t, self.bag_position)
        return out

    def tracking(self) -> dict[str, float]:
        """RMS and max position error, max attitude error over the commanded samples."""
        if not self.pos_error:
            return {"rms_position_error": float("nan"), "max_position_error": float("nan"),
                    "max_attitude_error": float("nan")}
        e = np.asarray(self.pos_error)
        return {"rms_position_error": float(np.sqrt(np.mean(e * e))),
                "max_position_error": float(e.max()),
                "max_attitude_error": float(np.max(self.att_error))}

    def clearance(self) -> dict[str, float | None]:
        def low(v):
            v = [x for x in v if x >= 0 and math.isfinite(x)]
            return float(min(v)) if v else None
        return {"min_robot_clearance": low(self.robot_clearance),
                "min_bag_clearance": low(self.bag_clearance),
                "contact_samples": int(sum(self.in_contact))}


def read_bag(bag_dir: str | os.PathLike, namespace: str = "",
             log_window: tuple[float, float] | None = None) -> Series:
    """The flight's series read back from a recorded rosbag2 (MCAP) directory; with
    `log_window` (wall-clock s) only the messages recorded in it (one leg of a multi-leg run,
    whose sim clock restarts at each reset)."""
    from roszen import typestore
    from roszen.bag.reader import BagReader

    ns = "/" + namespace.strip("/") + "/" if namespace.strip("/") else "/"
    handlers = {ns + POSE: "add_pose", ns + COMMAND: "add_command", ns + TRAJ: "add_traj",
                ns + CONTACTS: "add_contacts", ns + BAG_STATE: "add_bag"}
    series = Series()
    reader = BagReader(bag_dir)
    lo, hi = (log_window[0] * 1e9, log_window[1] * 1e9) if log_window else (-1.0, float("inf"))
    for m in reader.messages(list(handlers)):
        if not lo <= m.log_time_ns <= hi:
            continue
        try:
            msg = typestore.deserialize(m.data, m.topic.type)
            getattr(series, handlers[m.topic.name])(msg)
        except Exception:  # noqa: BLE001 - one bad record must not lose the plot
            continue
    return series


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


def _boxes_near(boxes: np.ndarray, pts: np.ndarray, margin: float = 2.0) -> np.ndarray:
    lo, hi = pts.min(axis=0) - margin, pts.max(axis=0) + margin
    keep = np.all(boxes[:, :3] <= hi, axis=1) & np.all(boxes[:, 3:] >= lo, axis=1)
    return boxes[keep]


def plot(series: Series, path: str | os.PathLike, boxes: np.ndarray, title: str = "",
         start: Iterable[float] | None = None, goal: Iterable[float] | None = None) -> Path:
    """PNG: path over the keep-in boxes from above (x-y) and from the side, tracking error and
    wall clearance over time."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    pos = np.asarray(series.position, float).reshape(-1, 3)
    ref = np.asarray(series.ref_position, float).reshape(-1, 3)
    bag = np.asarray(series.bag_position, float).reshape(-1, 3)
    pts = np.vstack([a for a in (pos, ref, bag) if len(a)] or [np.zeros((1, 3))])
    near = _boxes_near(np.asarray(boxes, float), pts)
    span = pts.max(axis=0) - pts.min(axis=0)
    side = (0, 2) if span[0] >= span[1] else (1, 2)  # look along the shorter horizontal axis
    fig, axes = plt.subplots(2, 2, figsize=(12, 9))
    names = "xyz"
    for ax, (i, j), label in ((axes[0, 0], (0, 1), "from above"), (axes[0, 1], side, "from the side")):
        for b in near:
            ax.add_patch(Rectangle((b[i], b[j]), b[i + 3] - b[i], b[j + 3] - b[j],
                                   facecolor="tab:green", alpha=0.08, edgecolor="tab:green", lw=0.8))
        if len(ref):
            ax.plot(ref[:, i], ref[:, j], "--", color="tab:gray", lw=1, label="reference")
        if len(pos):
            ax.plot(pos[:, i], pos[:, j], color="tab:blue", lw=1.5, label="robot")
        if len(bag):
            ax.plot(bag[:, i], bag[:, j], color="tab:orange", lw=1, label="bag")
        for p, mk, lab in ((start, "o", "start"), (goal, "*", "goal")):
            if p is not None:
                p = list(p)
                ax.plot(p[i], p[j], mk, color="k", ms=9, label=lab)
        lo, hi = pts.min(axis=0) - 1.0, pts.max(axis=0) + 1.0
        ax.set_xlim(lo[i], hi[i])
        ax.set_ylim(lo[j], hi[j])
        ax.set_aspect("equal")
        ax.set_xlabel(f"{names[i]} (m)")
        ax.set_ylabel(f"{names[j]} (m)")
        ax.set_title(f"path {label} (keep-in boxes in green)")
        ax.legend(fontsize=8, loc="best")
    ax = axes[1, 0]
    if series.err_t:
        t0 = series.err_t[0]
        ax.plot(np.asarray(series.err_t) - t0, series.pos_error, label="position error (m)")
        ax2 = ax.twinx()
        ax2.plot(np.asarray(series.err_t) - t0, series.att_error, color="tab:red", lw=0.8,
                 label="attitude error (rad)")
        ax2.set_ylabel("attitude error (rad)", color="tab:red")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("position error (m)")
    ax.set_title("tracking error")
    ax = axes[1, 1]
    if series.clear_t:
        t0 = series.clear_t[0]
        tt = np.asarray(series.clear_t) - t0
        rc = np.asarray(series.robot_clearance, float)
        bc = np.asarray(series.bag_clearance, float)
        ax.plot(tt, np.where(rc >= 0, rc, np.nan), label="robot")
        if np.any(bc >= 0):
            ax.plot(tt, np.where(bc >= 0, bc, np.nan), label="bag")
        ax.axhline(0.0, color="k", lw=0.6)
        ax.legend(fontsize=8)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("distance to wall (m)")
    ax.set_title("clearance")
    fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def finalize(run_dir: str | os.PathLike, bag_dir: str | os.PathLike) -> str:
    """After the graph stopped: re-draw each leg's plot from the closed bag and note the bag's
    figures in summary.json. Returns a one-line report."""
    from astrobee import config

    run_dir, bag_dir = Path(run_dir), Path(bag_dir)
    path = run_dir / "summary.json"
    if not path.exists():
        return f"[summary] no {path}: the mission did not report"
    data = json.loads(path.read_text())
    if not bag_dir.exists():
        data["bag"] = {"path": str(bag_dir), "error": "no bag recorded"}
        write_json(path, data)
        return f"[summary] {path} (no bag at {bag_dir})"
    try:
        series = read_bag(bag_dir)
        legs = data.get("legs", [])
        parts = [read_bag(bag_dir, log_window=(leg["wall_t0"], leg["wall_t1"]))
                 if leg.get("wall_t0") is not None and leg.get("wall_t1") is not None
                 else None for leg in legs]
    except Exception as exc:  # noqa: BLE001 - an unreadable bag is reported, not fatal
        data["bag"] = {"path": str(bag_dir), "error": str(exc)}
        write_json(path, data)
        return f"[summary] {path} (bag unreadable: {exc})"
    boxes = config.keep_in_boxes()
    for leg, part in zip(legs, parts):
        if part is None or not part.position:
            continue
        name = "plot.png" if len(legs) == 1 else f"plot_{leg['scenario']}.png"
        plot(part, run_dir / name, boxes, title=f"{leg['scenario']}: {leg.get('reason', '')} "
             "(from the recorded bag)", start=leg["start"][:3] if leg.get("start") else None,
             goal=leg["goal"][:3] if leg.get("goal") else None)
        leg["plot"] = name
        leg["plot_source"] = "bag"
        leg["bag_rms_position_error"] = part.tracking()["rms_position_error"]
    data["bag"] = {"path": str(bag_dir), "pose_samples": len(series.pose_t),
                   "command_samples": len(series.err_t), "contact_samples": len(series.clear_t)}
    if len(legs) == 1:
        data["plot"] = legs[0].get("plot", data.get("plot", ""))
    write_json(path, data)
    return (f"[summary] {path}: {'SUCCESS' if data.get('success') else 'FAILED'}; plots from "
            f"{bag_dir} ({len(series.pose_t)} poses)")
