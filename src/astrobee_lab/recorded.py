"""A recorded flight judged by the Task: the bag's topics turned into TaskSamples.

The window is the mission's: from the controller's first CONTROLLING state (/mob/state) to the
STOPPED (or IDLE) state after it; one sample per truth pose stamp in it, with the reference
(/gnc/ctl/traj, when the command is not idle), contacts and clearance (/sim/contacts), faults
(/sim/fault) and the bag's speed (/sim/bag/state) of the same stamp. Reading the bag needs
roszen (imported when called); the judgement itself is astrobee.task's.
"""
from __future__ import annotations

import os
from typing import Any

import numpy as np

from astrobee import msgconv as mc
from astrobee.task import Task, TaskMonitor, TaskSample, robot_named

CONTROLLING = 9
ENDED = (1, 2)          # IDLE, STOPPED


def _ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _v(x: Any) -> np.ndarray:
    return np.array([x.x, x.y, x.z], float)


def samples_from_bag(bag_dir: str | os.PathLike, namespace: str = "") -> list[TaskSample]:
    """The leg's TaskSamples of a recorded one-robot flight (see the module docstring)."""
    from roszen import typestore
    from roszen.bag.reader import BagReader

    pre = "/" + namespace.strip("/") + "/" if namespace.strip("/") else "/"
    robot = namespace.strip("/")
    topics = {pre + mc.POSE: "pose", pre + mc.TWIST: "twist", pre + mc.TRAJ: "traj",
              pre + mc.COMMAND: "command", mc.CONTACTS: "contacts",
              pre + mc.FAULT: "fault",
              mc.BAG_STATE: "bag", pre + mc.MOB_STATE: "mob"}
    by: dict[str, dict[int, Any]] = {k: {} for k in set(topics.values())}
    faults: list[tuple[int, str]] = []
    mob: list[tuple[int, int]] = []
    for m in BagReader(bag_dir).messages(list(topics)):
        kind = topics[m.topic.name]
        msg = typestore.deserialize(m.data, m.topic.type)
        if kind == "traj":
            by[kind][_ns(msg.when)] = msg
        elif kind == "mob":
            mob.append((_ns(msg.header.stamp), int(msg.state)))
        elif kind == "fault":
            if msg.active:
                faults.append((_ns(msg.header.stamp), f"{msg.source}: {msg.message} (code {msg.code})"))
        else:
            by[kind][_ns(msg.header.stamp)] = msg
    first = next((i for i, (_, s) in enumerate(mob) if s == CONTROLLING), None)
    if first is None:
        return []
    start = mob[first][0]
    # the first stop after CONTROLLING, in the order the states were published
    end = next((t for t, s in mob[first:] if s in ENDED), max(by["pose"], default=start))
    out = []
    active: list[str] = []
    for t in sorted(k for k in by["pose"] if start <= k <= end):
        pose = by["pose"][t]
        p, q = mc.pose(pose.pose)
        tw = by["twist"].get(t)
        vel = None if tw is None else {robot: (_v(tw.twist.linear), _v(tw.twist.angular))}
        cmd, traj = by["command"].get(t), by["traj"].get(t)
        ref = ({robot: _v(traj.pose.position)} if traj is not None and cmd is not None
               and int(cmd.control_mode) != 0 else None)
        c = by["contacts"].get(t)
        active += [text for ft, text in faults if ft <= t and text not in active]
        bag = by["bag"].get(t)
        speed = (float(np.linalg.norm(_v(bag.velocity) - _v(tw.twist.linear)))
                 if bag is not None and tw is not None else float("nan"))
        out.append(TaskSample(
            t=t * 1e-9, poses={robot: (p, q)}, velocities=vel, reference=ref,
            contacts=0 if c is None else len(c.contacts) or int(bool(c.in_contact)),
            contact_bodies=() if c is None else tuple(sorted({f"{x.body_a}-{x.body_b}"
                                                              for x in c.contacts})),
            touching=() if c is None else tuple(sorted({str(x.body_a) for x in c.contacts})),
            robot_clearance=float("nan") if c is None else float(c.robot_clearance),
            bag_clearance=float("nan") if c is None else float(c.bag_clearance),
            faults={robot: tuple(active)} if active else {}, bag_robot_speed=speed))
    return out


def judge_bag(bag_dir: str | os.PathLike, task: Task, namespace: str = "") -> TaskMonitor:
    """A TaskMonitor fed with the recorded leg (verdict() and metrics() as for a live one);
    a recording with no CONTROLLING state fails with that cause."""
    monitor = task.monitor()
    samples = samples_from_bag(bag_dir, namespace)
    if not samples:
        monitor.fail(f"{robot_named(namespace.strip('/'))}: no controlled flight in the recording")
    for s in samples:
        monitor.update(s)
    return monitor
