"""The time series of one robot's flight (sim time, s), fed from messages live (the mission's
subscriptions) or read back from the run's recording (`read_bag`, through the one recording
reader astrobee_lab.recording), and its figures of merit (tracking, clearance, contacts)."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from astrobee.msgconv import COMMAND, POSE, TRAJ
from astrobee.msgconv import stamp_s as _t
from astrobee.task import robot_label as contact_name

# global topics (absolute names)
CONTACTS = "sim/contacts"
BAG_STATE = "sim/bag/state"


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
    cargo_clearance: list[float] = field(default_factory=list)
    in_contact: list[bool] = field(default_factory=list)
    contact_bodies: set[str] = field(default_factory=set)
    contact_names: list[tuple[str, ...]] = field(default_factory=list)   # bodies touching, per sample
    cargo_t: list[float] = field(default_factory=list)
    cargo_position: list[list[float]] = field(default_factory=list)
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
        self.cargo_clearance.append(float(msg.bag_clearance))
        self.in_contact.append(bool(msg.in_contact))
        names = tuple(sorted({str(c.body_a) for c in msg.contacts}))
        self.contact_names.append(names)
        for c in msg.contacts:
            self.contact_bodies.add(f"{c.body_a}-{c.body_b}")

    def add_cargo(self, msg: Any) -> None:
        p = msg.pose.position
        self.cargo_t.append(_t(msg.header.stamp))
        self.cargo_position.append([p.x, p.y, p.z])

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
        out.clear_t, out.robot_clearance, out.cargo_clearance, out.in_contact, out.contact_names = cut(
            self.clear_t, self.robot_clearance, self.cargo_clearance, self.in_contact,
            self.contact_names)
        out.cargo_t, out.cargo_position = cut(self.cargo_t, self.cargo_position)
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
        from astrobee.station import robot_radius
        c = KeepIn(config.keep_in_boxes()).clearance(np.asarray(self.position, float), reach=1.0)
        return float(np.min(c)) - robot_radius()

    def clearance(self) -> dict[str, float | None]:
        def low(v):
            v = [x for x in v if x >= 0 and math.isfinite(x)]
            return float(min(v)) if v else None
        return {"min_robot_clearance": low(self.robot_clearance),
                "min_bag_clearance": low(self.cargo_clearance),
                "contact_samples": int(sum(self.in_contact))}


# contact_name(robot): the simulator's name of a robot in /sim/contacts ("robot" for the
# default one); robot_named(robot): how reasons name it ("robot bumble", "the default robot");
# both astrobee.task's, so the summary and the Task word a cause alike.


def robot_label(robot: str) -> str:
    """How plots name a robot: its namespace, "robot" for the default one."""
    return contact_name(robot)


def read_bag(bag_dir: str | os.PathLike, namespace: str = "",
             log_window: tuple[float, float] | None = None) -> Series:
    """One robot's series (with the global contacts and cargo bag) read back from the recording
    (a rosbag2 MCAP directory); with
    `log_window` (wall-clock s) only the messages recorded in it (one leg of a multi-leg run,
    whose sim clock restarts at each reset)."""
    from astrobee_lab.recording import read

    ns = "/" + namespace.strip("/") + "/" if namespace.strip("/") else "/"
    handlers = {ns + POSE: "add_pose", ns + COMMAND: "add_command", ns + TRAJ: "add_traj",
                "/" + CONTACTS: "add_contacts", "/" + BAG_STATE: "add_cargo"}   # these two are global
    series = Series()
    for m in read(bag_dir, handlers, log_window):
        try:
            getattr(series, handlers[m.topic])(m.msg)
        except Exception:  # noqa: BLE001 - one bad record must not lose the plot
            continue
    return series
