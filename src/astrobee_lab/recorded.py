"""A recorded flight judged by the Task: the bag's topics turned into TaskSamples.

The window is the mission's: the leg starts when the controller follows its segment (its first
CONTROLLING state on /mob/state, or the segment's first stamp if later) and the Task's budget
is that segment's duration + the settle budget; samples are fed from the start until the Task
says the leg is over (every robot at rest at its goal, a fault, or the budget out), as the
mission ends it. The samples are astrobee.leg_samples' (the mission's builder); the bag is
read through astrobee_lab.recording (roszen imported when called); the judgement itself is
astrobee.task's.
"""
from __future__ import annotations

import os
from dataclasses import replace
from typing import Any

from astrobee import msgconv as mc
from astrobee.leg_samples import LegSamples
from astrobee.task import Task, TaskMonitor, TaskSample, judge, robot_named

CONTROLLING = mc.MotionState.CONTROLLING


class RecordedLeg:
    """One robot's recorded leg: its samples, the leg's start (sim ns) and plan duration (s)."""

    def __init__(self, samples: LegSamples, start_ns: int | None, plan_duration: float | None):
        self.builder = samples
        self.start_ns = start_ns
        self.plan_duration = plan_duration

    def samples(self) -> list[TaskSample]:
        return [] if self.start_ns is None else list(self.builder.samples(self.start_ns))


def read_leg(bag_dir: str | os.PathLike, namespace: str = "") -> RecordedLeg:
    """The recorded one-robot flight's messages and window (see the module docstring)."""
    from .recording import read

    pre = "/" + namespace.strip("/") + "/" if namespace.strip("/") else "/"
    robot = namespace.strip("/")
    b = LegSamples([robot])
    feed = {pre + mc.POSE: lambda m: b.add_pose(robot, m),
            pre + mc.TWIST: lambda m: b.add_twist(robot, m),
            pre + mc.TRAJ: lambda m: b.add_traj(robot, m),
            pre + mc.COMMAND: lambda m: b.add_command(robot, m),
            pre + mc.FAULT: lambda m: b.add_fault(robot, m),
            mc.CONTACTS: b.add_contacts, mc.BAG_STATE: b.add_cargo}
    controlling: list[int] = []
    segments: list[Any] = []
    topics = [*feed, pre + mc.MOB_STATE, pre + mc.SEGMENT]
    for m in read(bag_dir, topics):
        msg = m.msg
        if m.topic == pre + mc.MOB_STATE:
            if int(msg.state) == CONTROLLING:
                controlling.append(mc.stamp_ns(msg.header.stamp))
        elif m.topic == pre + mc.SEGMENT:
            segments.append(msg)
        else:
            feed[m.topic](msg)
    if not controlling:
        return RecordedLeg(b, None, None)
    start, duration = controlling[0], None
    if segments and segments[0].segment:        # the first leg's (as the first CONTROLLING)
        whens = [mc.stamp_ns(s.when) for s in segments[0].segment]
        start = max(start, whens[0])
        duration = (whens[-1] - whens[0]) * 1e-9
    return RecordedLeg(b, start, duration)


def samples_from_bag(bag_dir: str | os.PathLike, namespace: str = "") -> list[TaskSample]:
    """The leg's TaskSamples of a recorded one-robot flight, from its start on."""
    return read_leg(bag_dir, namespace).samples()


def judge_bag(bag_dir: str | os.PathLike, task: Task, namespace: str = "") -> TaskMonitor:
    """A TaskMonitor fed with the recorded leg until the Task ends it (verdict() and metrics()
    as for a live one); the task's budget is the recorded plan's unless it has a plan already;
    a recording with no CONTROLLING state fails with that cause."""
    leg = read_leg(bag_dir, namespace)
    if leg.start_ns is not None:
        start = leg.start_ns * 1e-9
        if task.plan_end is None and leg.plan_duration is not None:
            task = task.with_plan(leg.plan_duration, start_time=start)
        else:
            task = replace(task, start_time=start)
    samples = leg.samples()
    why = "" if samples else \
        f"{robot_named(namespace.strip('/'))}: no controlled flight in the recording"
    return judge(task, samples, why)
