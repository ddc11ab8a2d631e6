"""A leg's TaskSamples from its messages, live (the mission) or read back from a recording
(astrobee_lab.recorded): one builder, so both judge the same samples the same way.

One sample per truth pose stamp of the first robot (sim ns) for which every robot's truth pose
and twist are in (/loc/truth/pose, /loc/truth/twist; a stamp with a message lost is passed
over), with the reference of the same stamp (/gnc/ctl/traj, when the command of that stamp is
not idle), contacts and clearance
(/sim/contacts), the bag's speed relative to the first robot (/sim/bag/state) and the faults
raised up to it (/sim/fault). Messages are duck-typed (attributes as in astrobee_msgs): the
core needs no transport.
"""
from __future__ import annotations

import bisect
from typing import Any, Iterator

import numpy as np

from . import msgconv as mc
from .task import TaskSample


STALE_NS = 200_000_000       # a stamp still incomplete this long after the newest pose: passed


def _v(x: Any) -> np.ndarray:
    return np.array([x.x, x.y, x.z], float)


class LegSamples:
    """Messages of one leg by stamp, and the TaskSamples they make (see the module docstring)."""

    def __init__(self, robots: list[str]) -> None:
        self.robots = list(robots) or [""]
        self.first = self.robots[0]
        self.pose: dict[str, dict[int, tuple[np.ndarray, np.ndarray]]] = {r: {} for r in self.robots}
        self.twist: dict[str, dict[int, tuple[np.ndarray, np.ndarray]]] = {r: {} for r in self.robots}
        self.ref: dict[str, dict[int, tuple[np.ndarray, np.ndarray]]] = {r: {} for r in self.robots}
        self.mode: dict[str, dict[int, int]] = {r: {} for r in self.robots}
        self.contacts: dict[int, tuple[int, tuple[str, ...], tuple[str, ...], float, float]] = {}
        self.cargo_v: dict[int, np.ndarray] = {}
        self.faults: dict[str, list[tuple[int, str]]] = {r: [] for r in self.robots}
        self._order: list[int] = []          # the first robot's pose stamps, sorted
        self._live_last = -1

    # ---- feeding (one method per topic) ---------------------------------------------------
    def add_pose(self, robot: str, msg: Any) -> None:
        t = mc.stamp_ns(msg.header.stamp)
        if robot == self.first and t not in self.pose[robot]:
            bisect.insort(self._order, t)
        self.pose[robot][t] = mc.pose(msg.pose)

    def add_twist(self, robot: str, msg: Any) -> None:
        self.twist[robot][mc.stamp_ns(msg.header.stamp)] = (_v(msg.twist.linear),
                                                            _v(msg.twist.angular))

    def add_traj(self, robot: str, msg: Any) -> None:
        self.ref[robot][mc.stamp_ns(msg.when)] = mc.pose(msg.pose)

    def add_command(self, robot: str, msg: Any) -> None:
        self.mode[robot][mc.stamp_ns(msg.header.stamp)] = int(msg.control_mode)

    def add_contacts(self, msg: Any) -> None:
        n = len(msg.contacts) or int(bool(msg.in_contact))
        self.contacts[mc.stamp_ns(msg.header.stamp)] = (
            n, tuple(sorted({f"{c.body_a}-{c.body_b}" for c in msg.contacts})),
            tuple(sorted({str(c.body_a) for c in msg.contacts})),
            float(msg.robot_clearance), float(msg.bag_clearance))

    def add_cargo(self, msg: Any) -> None:
        self.cargo_v[mc.stamp_ns(msg.header.stamp)] = _v(msg.velocity)

    def add_fault(self, robot: str, msg: Any) -> None:
        if msg.active:
            self.faults[robot].append((mc.stamp_ns(msg.header.stamp),
                                       f"{msg.source}: {msg.message} (code {msg.code})"))

    # ---- samples --------------------------------------------------------------------------
    def stamps(self, start_ns: int | None = None, end_ns: int | None = None) -> list[int]:
        """The first robot's pose stamps in [start_ns, end_ns], in order."""
        i = 0 if start_ns is None else bisect.bisect_left(self._order, start_ns)
        j = len(self._order) if end_ns is None else bisect.bisect_right(self._order, end_ns)
        return self._order[i:j]

    def complete(self, t: int) -> bool:
        """Every robot's pose and twist of stamp t are in."""
        return all(t in self.pose[r] and t in self.twist[r] for r in self.robots)

    def sample(self, t: int) -> TaskSample:
        """The TaskSample of pose stamp t (ns)."""
        poses = {r: self.pose[r][t] for r in self.robots if t in self.pose[r]}
        vel = {r: self.twist[r][t] for r in self.robots if t in self.twist[r]}
        refs = {r: self.ref[r][t] for r in self.robots
                if t in self.ref[r] and self.mode[r].get(t, 0) != 0}
        c = self.contacts.get(t)
        faults = {r: tuple(dict.fromkeys(text for ft, text in self.faults[r] if ft <= t))
                  for r in self.robots}
        cargo, tw = self.cargo_v.get(t), vel.get(self.first)
        speed = (float(np.linalg.norm(cargo - tw[0])) if cargo is not None and tw is not None
                 else float("nan"))
        return TaskSample(
            t=t * 1e-9, poses=poses, velocities=vel or None,
            reference={r: p for r, (p, _) in refs.items()} or None,
            reference_attitude={r: q for r, (_, q) in refs.items()} or None,
            contacts=0 if c is None else c[0], contact_bodies=() if c is None else c[1],
            touching=() if c is None else c[2],
            robot_clearance=float("nan") if c is None else c[3],
            bag_clearance=float("nan") if c is None else c[4],
            faults={r: f for r, f in faults.items() if f}, bag_robot_speed=speed)

    def samples(self, start_ns: int | None = None, end_ns: int | None = None
                ) -> Iterator[TaskSample]:
        """Every complete sample (every robot's pose and twist in) with start_ns <= t <=
        end_ns, in time order: a stamp whose twist was lost (a dropped message) is passed
        over, as the live feed passes it."""
        for t in self.stamps(start_ns, end_ns):
            if self.complete(t):
                yield self.sample(t)

    def new_samples(self, start_ns: int) -> Iterator[TaskSample]:
        """Live: the samples from start_ns on whose poses and twists are all in and that come
        after the last one given (a stamp completed after a later one was given is skipped
        here; samples() has it)."""
        newest = self._order[-1] if self._order else -1
        for t in self.stamps(max(start_ns, self._live_last + 1)):
            if not self.complete(t):
                if newest - t < STALE_NS:
                    break
                continue            # a twist that never came: the stamp is passed over
            self._live_last = t
            yield self.sample(t)
