"""The plot of a leg (PNG, read at a glance): every robot's path and reference (and the cargo
bag's) over the labelled keep-in modules from above and from the side, position and attitude
error per robot, clearance of robots and cargo bag, and where and why a failed leg failed."""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from astrobee_bringup.series import Series, robot_label


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
    cargo = np.asarray(first.cargo_position, float).reshape(-1, 3)
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
        bc = np.asarray(first.cargo_clearance, float)
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
