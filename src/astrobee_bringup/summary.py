"""Run summary: time series of a flight (live or read back from the recording), its figures of
merit per robot, the verdict of a leg (`leg_verdict`: every robot at its goal, no contact, no
fault; decided by astrobee.task's TaskMonitor, so the mission and the Task never disagree),
summary.json and the plot PNG (every robot's path over the labelled modules, tracking errors,
clearance, and where and why a failed leg failed).

Wording: "cargo bag" is the carried bag; "recording" is the rosbag2 directory of the run.
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
from astrobee.task import Goal, Task, TaskMonitor  # noqa: E402
from astrobee.task import robot_label as contact_name  # noqa: E402,F401
from astrobee.task import robot_named  # noqa: E402,F401
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
    contact_names: list[tuple[str, ...]] = field(default_factory=list)   # bodies touching, per sample
    bag_t: list[float] = field(default_factory=list)
    bag_position: list[list[float]] = field(default_factory=list)
    controlling: list[tuple[float, float]] = field(default_factory=list)  # CONTROLLING spans

    # ---- feeding from messages (live subscriptions or a recording) -------------------------
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
        names = tuple(sorted({str(c.body_a) for c in msg.contacts}))
        self.contact_names.append(names)
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
        out.clear_t, out.robot_clearance, out.bag_clearance, out.in_contact, out.contact_names = cut(
            self.clear_t, self.robot_clearance, self.bag_clearance, self.in_contact,
            self.contact_names)
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

    def contact_samples(self, body: str) -> int:
        """Samples in which `body` (a robot's contact name, see contact_name, or "bag") touched
        the station."""
        return int(sum(body in names for names in self.contact_names))

    def first_contact(self, body: str | None = None) -> float | None:
        """Sim time of the first contact (of `body`, or of anything), None without one."""
        if body is None:
            return next((t for t, c in zip(self.clear_t, self.in_contact) if c), None)
        return next((t for t, n in zip(self.clear_t, self.contact_names) if body in n), None)

    def robot_min_clearance(self) -> float | None:
        """Smallest distance (m) of the robot's envelope (planner radius) to the keep-in boundary
        along its recorded path; negative when it left the keep-in set."""
        if not self.position:
            return None
        from astrobee import config
        from astrobee_control.clearance import KeepIn
        from astrobee_planning.boxes import robot_radius
        c = KeepIn(config.keep_in_boxes()).clearance(np.asarray(self.position, float), reach=1.0)
        return float(np.min(c)) - robot_radius()

    def clearance(self) -> dict[str, float | None]:
        def low(v):
            v = [x for x in v if x >= 0 and math.isfinite(x)]
            return float(min(v)) if v else None
        return {"min_robot_clearance": low(self.robot_clearance),
                "min_bag_clearance": low(self.bag_clearance),
                "contact_samples": int(sum(self.in_contact))}


# contact_name(robot): the simulator's name of a robot in /sim/contacts ("robot" for the
# default one); robot_named(robot): how reasons name it ("robot bumble", "the default robot");
# both astrobee.task's, so the summary and the Task word a cause alike.


def robot_label(robot: str) -> str:
    """How plots name a robot: its namespace, "robot" for the default one."""
    return contact_name(robot)


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


def task_monitor(robots: list[RobotResult], tolerance_position: float | None,
                 tolerance_attitude: float | None, cargo_contacts: int = 0,
                 aborted: str = "") -> TaskMonitor:
    """The Task's monitor holding a leg's end figures (astrobee.task decides, not this module):
    each robot's final errors, contact samples and faults, the cargo bag's contacts, an abort."""
    def goal(r: RobotResult) -> Goal:
        g = list(r.goal) if len(r.goal) == 7 else [0.0] * 6 + [1.0]
        return Goal(np.asarray(g[:3], float), np.asarray(g[3:], float))
    task = Task({r.name: goal(r) for r in robots}, tolerance_position, tolerance_attitude)
    touches = {contact_name(r.name): r.contacts for r in robots}
    touches["bag"] = cargo_contacts
    return TaskMonitor.from_figures(
        task, {r.name: (r.final_position_error, r.final_attitude_error) for r in robots},
        touches, {r.name: list(r.faults) for r in robots}, aborted)


def robot_problems(r: RobotResult, tolerance_position: float | None,
                   tolerance_attitude: float | None) -> list[str]:
    """What keeps one robot from success in a leg (empty: it reached its goal within the
    tolerances, with no contact and no fault): the Task's judgement of its figures."""
    return task_monitor([r], tolerance_position, tolerance_attitude).robot_problems(r.name)


def leg_verdict(robots: list[RobotResult], tolerance_position: float | None,
                tolerance_attitude: float | None, cargo_contacts: int = 0,
                aborted: str = "") -> tuple[bool, str]:
    """A leg succeeds only if every robot reaches its goal with no contact and no fault, and the
    cargo bag touches nothing (the Task's verdict of the leg's end figures). Sets each robot's
    success/reason/reached_goal; returns (success, reason), the reason naming each failing robot
    (single robot: its problems alone)."""
    if not robots:
        return False, aborted or "no robot flown"
    monitor = task_monitor(robots, tolerance_position, tolerance_attitude, cargo_contacts, aborted)
    for r in robots:
        probs = monitor.robot_problems(r.name)
        r.reached_goal = not any(p.startswith("final") for p in probs)
        r.success = not probs
        r.reason = "goal reached" if not probs else "; ".join(probs)
    return monitor.verdict()


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


def read_bag(bag_dir: str | os.PathLike, namespace: str = "",
             log_window: tuple[float, float] | None = None) -> Series:
    """One robot's series (with the global contacts and cargo bag) read back from the recording
    (a rosbag2 MCAP directory); with
    `log_window` (wall-clock s) only the messages recorded in it (one leg of a multi-leg run,
    whose sim clock restarts at each reset)."""
    from roszen import typestore
    from roszen.bag.reader import BagReader

    ns = "/" + namespace.strip("/") + "/" if namespace.strip("/") else "/"
    handlers = {ns + POSE: "add_pose", ns + COMMAND: "add_command", ns + TRAJ: "add_traj",
                "/" + CONTACTS: "add_contacts", "/" + BAG_STATE: "add_bag"}   # these two are global
    series = Series()
    reader = BagReader(bag_dir)
    lo, hi = (log_window[0] * 1e9, log_window[1] * 1e9) if log_window else (-1.0, float("inf"))
    for m in reader.messages(list(handlers)):
        if not lo <= m.publish_time_ns <= hi:   # wall receive time (log time may be sim time)
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


ROBOT_COLOURS = ("tab:blue", "tab:purple", "tab:green", "tab:brown")
CARGO_COLOUR = "tab:orange"


def _module_labels(view: tuple[int, int], lo: np.ndarray, hi: np.ndarray
                   ) -> list[tuple[str, float, float]]:
    """(module name, label position) for each module seen in the window [lo, hi] (3-vectors):
    at the centre of the visible part of its box that shows most; hatches ('/') unlabelled."""
    from astrobee import config
    best: dict[str, tuple[float, float, float]] = {}
    i, j = view
    for k in config.iss()["keep_in"]:
        name, b = str(k["module"]), np.asarray(k["box"], float)
        if "/" in name:
            continue
        a_lo, a_hi = np.maximum(b[:3], lo), np.minimum(b[3:], hi)
        if np.any(a_hi <= a_lo):
            continue        # not in the window (along any axis: the view's depth included)
        area = float((a_hi[i] - a_lo[i]) * (a_hi[j] - a_lo[j]))
        if name not in best or area > best[name][0]:
            # near the top of the visible part: the path usually runs through the middle
            best[name] = (area, 0.5 * (a_lo[i] + a_hi[i]), a_hi[j] - 0.15 * (a_hi[j] - a_lo[j]))
    return [(n.replace("_", " ").upper() if len(n) <= 3 else n.replace("_", " "), u, v)
            for n, (_, u, v) in best.items()]


def _smooth(y: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average over n samples (the curve under sensor noise)."""
    if n <= 1 or len(y) < n:
        return y
    k = np.ones(n) / n
    pad = np.pad(y, (n // 2, n - 1 - n // 2), mode="edge")
    return np.convolve(pad, k, mode="valid")


def _unit(peak: float) -> tuple[float, str]:
    """Millimetres for errors under 0.1 m, metres above."""
    return (1000.0, "mm") if peak < 0.1 else (1.0, "m")


def plot(series: "Series | dict[str, Series]", path: str | os.PathLike, boxes: np.ndarray,
         title: str = "", start: Iterable[float] | None = None, goal: Iterable[float] | None = None,
         robots: list[dict[str, Any]] | None = None, t0: float | None = None,
         success: bool | None = None) -> Path:
    """PNG read at a glance: every robot's path (and its reference, and the cargo bag's) over
    the keep-in boxes with the module names, from above and from the side; position and
    attitude error per robot (mm under 0.1 m, noise averaged over 1 s over the raw trace);
    clearance of robots and cargo bag; a failed leg marks where and why each robot failed.

    series: one Series, or robot name -> Series; robots: summary entries (RobotResult as
    dicts: start, goal, failed_at) in the same order; t0: sim time of the leg's start."""
    import textwrap

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    per = series if isinstance(series, dict) else {"": series}
    names = list(per)
    info = {str(r.get("name", "")): r for r in (robots or [])}
    if not robots and (start is not None or goal is not None):
        info[names[0]] = {"start": list(start or []), "goal": list(goal or [])}
    first = per[names[0]]
    arrays = {n: (np.asarray(s.position, float).reshape(-1, 3),
                  np.asarray(s.ref_position, float).reshape(-1, 3)) for n, s in per.items()}
    cargo = np.asarray(first.bag_position, float).reshape(-1, 3)
    ends = [np.asarray(r[k][:3], float)[None] for r in info.values() for k in ("start", "goal")
            if len(r.get(k) or []) >= 3]     # the whole route is in view, even when cut short
    pts = np.vstack([a for pr in arrays.values() for a in pr if len(a)]
                    + ([cargo] if len(cargo) else []) + ends or [np.zeros((1, 3))])
    if t0 is None:
        starts = [s.pose_t[0] for s in per.values() if s.pose_t]
        t0 = min(starts) if starts else 0.0
    near = _boxes_near(np.asarray(boxes, float), pts)
    span = pts.max(axis=0) - pts.min(axis=0)
    long_ax, short_ax = (0, 1) if span[0] >= span[1] else (1, 0)   # the path runs along long_ax
    views = (((long_ax, short_ax), "from above"), ((long_ax, 2), "from the side"))
    fig = plt.figure(figsize=(15, 11))
    gs = fig.add_gridspec(3, 3, height_ratios=[1.0, 1.0, 1.3], hspace=0.45, wspace=0.35)
    axis_names = "xyz"
    colour = {n: ROBOT_COLOURS[k % len(ROBOT_COLOURS)] for k, n in enumerate(names)}
    failures = [(n, info[n]["failed_at"]) for n in names if info.get(n, {}).get("failed_at")]
    for row, ((i, j), label) in enumerate(views):
        ax = fig.add_subplot(gs[row, :])
        for b in near:
            ax.add_patch(Rectangle((b[i], b[j]), b[i + 3] - b[i], b[j + 3] - b[j],
                                   facecolor="tab:green", alpha=0.06, edgecolor="tab:green", lw=0.6))
        lo, hi = pts.min(axis=0) - 0.8, pts.max(axis=0) + 0.8
        for text, u, v in _module_labels((i, j), lo, hi):
            ax.text(u, v, text, ha="center", va="center", fontsize=13, color="darkgreen",
                    alpha=0.4, weight="bold", zorder=0)
        for n in names:
            pos, ref = arrays[n]
            who = robot_label(n) if len(names) > 1 else "robot"
            if len(ref):   # wide and pale under the robot's line: both visible when they overlap
                ax.plot(ref[:, i], ref[:, j], color=colour[n], lw=5, alpha=0.25,
                        solid_capstyle="round", label=f"{who} reference")
            if len(pos):
                ax.plot(pos[:, i], pos[:, j], color=colour[n], lw=1.3, label=f"{who} flown")
            r = info.get(n, {})
            for key, mk, what in (("start", "o", "start"), ("goal", "*", "goal")):
                p = r.get(key) or []
                if len(p) >= 3:
                    ax.plot(p[i], p[j], mk, color=colour[n], mec="k", ms=12 if mk == "*" else 7,
                            zorder=4)
                    if n == names[0]:   # one legend entry per marker kind
                        ax.plot([], [], mk, color="w", mec="k", ms=12 if mk == "*" else 7,
                                label=what)
        if len(cargo):
            ax.plot(cargo[:, i], cargo[:, j], color=CARGO_COLOUR, lw=1, ls="-.", label="cargo bag")
        for k, (n, f) in enumerate(failures):
            p = f.get("position") or []
            if len(p) >= 3:
                when = f" at t={float(f['t']) - t0:.1f} s" if f.get("t") is not None else ""
                ax.plot(p[i], p[j], "X", color="red", ms=14, mec="k", zorder=5)
                right = p[i] > 0.5 * (pts[:, i].min() + pts[:, i].max())
                ax.annotate(f"{robot_label(n)}{when}: {textwrap.shorten(str(f.get('why', '')), 70)}",
                            (p[i], p[j]), xytext=(-12 if right else 12, 14 + 18 * k),
                            textcoords="offset points", ha="right" if right else "left",
                            color="red", fontsize=9, weight="bold",
                            bbox=dict(boxstyle="round", fc="white", ec="red", alpha=0.85))
        ax.set_xlim(lo[i], hi[i])
        ax.set_ylim(lo[j], hi[j])
        ax.set_aspect("equal")
        ax.set_xlabel(f"{axis_names[i]} (m)")
        ax.set_ylabel(f"{axis_names[j]} (m)")
        ax.set_title(f"path {label} (keep-in boxes in green)", fontsize=10)
        if row == 0:        # one legend for both views, outside the data
            ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)

    def mark_failures(ax) -> None:
        for n, f in failures:
            if f.get("t") is not None:
                ax.axvline(float(f["t"]) - t0, color="red", ls="--", lw=1)
                ax.text(float(f["t"]) - t0, 1.0, f" {robot_label(n)} failed", color="red",
                        fontsize=8, va="top", transform=ax.get_xaxis_transform())

    def error_panel(ax, field: str, what: str) -> None:
        peak = max((float(np.max(getattr(s, field))) for s in per.values() if getattr(s, field)),
                   default=0.0)
        if field == "pos_error":
            scale, unit = _unit(peak)
        else:
            scale, unit = 180.0 / math.pi, "deg"
        for n, s in per.items():
            if not s.err_t:
                continue
            t = np.asarray(s.err_t) - t0
            y = np.asarray(getattr(s, field), float) * scale
            who = robot_label(n) if len(names) > 1 else "robot"
            ax.plot(t, y, color=colour[n], lw=0.6, alpha=0.3)          # raw samples
            ax.plot(t, _smooth(y, 62), color=colour[n], lw=1.5, label=f"{who} (1 s mean)")
        mark_failures(ax)
        ax.set_xlabel("time since the start (s)")
        ax.set_ylabel(f"{what} ({unit})")
        ax.set_title(f"{what} (pale: raw samples)", fontsize=10)
        ax.set_ylim(bottom=0)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2)

    error_panel(fig.add_subplot(gs[2, 0]), "pos_error", "position error")
    error_panel(fig.add_subplot(gs[2, 1]), "att_error", "attitude error")
    ax = fig.add_subplot(gs[2, 2])
    if first.clear_t:
        tt = np.asarray(first.clear_t) - t0
        rc = np.asarray(first.robot_clearance, float)
        bc = np.asarray(first.bag_clearance, float)
        ax.plot(tt, np.where(rc >= 0, rc, np.nan), color="tab:blue",
                label="robots (nearest)" if len(names) > 1 else "robot")
        if np.any(bc >= 0):
            ax.plot(tt, np.where(bc >= 0, bc, np.nan), color=CARGO_COLOUR, label="cargo bag")
        hit = np.asarray(first.in_contact, bool)
        if hit.any():
            ax.plot(tt[hit], np.zeros(int(hit.sum())), "|", color="red", ms=12, label="contact")
        ax.axhline(0.0, color="k", lw=0.6)
        ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3)
    mark_failures(ax)
    ax.set_xlabel("time since the start (s)")
    ax.set_ylabel("distance to wall (m)")
    ax.set_title("clearance", fontsize=10)
    ok = success if success is not None else None
    fig.suptitle("\n".join(textwrap.wrap(title, 130)), fontsize=12,
                 color={True: "darkgreen", False: "firebrick", None: "black"}[ok])
    path = Path(path)
    fig.savefig(path, dpi=80, bbox_inches="tight")
    plt.close(fig)
    return path


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
