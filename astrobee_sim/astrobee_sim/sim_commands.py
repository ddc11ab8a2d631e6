"""sim_node's command inbox: each robot's <ns>/gnc/ctl/command (FamCommand, BODY wrench) taken
from the wire to the backend, with the stamps lockstep counts.

A command is read in place from its CDR bytes (tick_wire.decode_command) when its layout is the
plain one, else decoded whole (malformed bytes are logged and dropped). It is dropped with a
rate-limited warning when stamped more than `command_max_lead` ahead of sim time (an answer to a
state from before a reset) or refused by the backend; a stamp answers one tick at most.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from astrobee import msgconv as mc

from .tick_wire import decode_command


class CommandInbox:
    """Per-robot command subscriptions and the stamps of the last commands (see the module)."""

    def __init__(self, host: Any, command_max_lead: float) -> None:
        """host: the SimNode (node, sim, names, now_ns(), warn(), log)."""
        from roszen import runtime as roszen
        self.host = host
        self.max_lead_ns = int(command_max_lead * 1e9)
        self.support = roszen.codec.msg_support("astrobee_msgs/msg/FamCommand")
        self.topic: dict[str, str] = {}          # robot -> its command topic
        self.stamp: dict[str, int] = {}          # robot -> tick answered (ns), -1: none yet
        self.raw_stamp: dict[str, int] = {}      # robot -> stamp of its last command

    def add_robot(self, name: str) -> None:
        """Subscribe to a robot's command topic (once per robot name)."""
        if name in self.topic:
            return
        self.topic[name] = topic = mc.robot_topic(name, mc.COMMAND)
        self.stamp[name] = self.raw_stamp[name] = -1
        self.host.node.create_subscription("astrobee_msgs/msg/FamCommand", topic,
                                           lambda data, nm=name: self.on_cdr(nm, data), 10,
                                           raw=True)

    def forget(self) -> None:
        """After a reset: no tick is answered yet (sim time restarts at 0)."""
        for name in self.stamp:
            self.stamp[name] = self.raw_stamp[name] = -1

    def late(self, t: int, first: bool) -> list[str]:
        """Lockstep: the robots (topic names, '/' for the default) whose command for the tick
        at `t` ns has not come. A robot counts once its command topic has a publisher or it
        has sent a command; at the first tick with none yet: ['(no controller yet)']."""
        host = self.host
        want = [n for n in self.topic if n in host.names and
                (self.stamp[n] >= 0 or host.node.count_publishers(self.topic[n]) > 0)]
        if first and not want:
            return ["(no controller yet)"]
        return [n or "/" for n in want if self.stamp[n] < t]

    def on_cdr(self, name: str, data: bytes) -> None:
        """A FamCommand's CDR bytes: the stamp and wrench read in place when the layout is the
        plain one (little-endian, exact length), else the whole message decoded."""
        cmd = decode_command(data)
        if cmd is not None:
            self.command(name, *cmd)
            return
        try:
            msg = self.support.deserialize(data)
        except Exception as exc:  # noqa: BLE001 - as the subscription would: drop and say so
            self.host.log.error(f"dropped a sample on {self.topic[name]}: malformed CDR "
                                f"payload ({len(data)} bytes) for astrobee_msgs/msg/FamCommand: {exc}")
            return
        self.on_message(name, msg)

    def on_message(self, name: str, msg: Any) -> None:
        """A decoded FamCommand (the slow path of on_cdr)."""
        try:
            w = msg.wrench
            wrench = [float(w.force.x), float(w.force.y), float(w.force.z), float(w.torque.x),
                      float(w.torque.y), float(w.torque.z)]
            stamp = mc.stamp_ns(msg.header.stamp)
        except (AttributeError, TypeError, ValueError) as exc:
            self.host.warn("badcmd", f"malformed command for robot {name!r} dropped: {exc}")
            return
        self.command(name, stamp, wrench)

    def command(self, name: str, stamp: int, wrench: Any) -> None:
        """Hold a robot's commanded body wrench stamped `stamp` (ns), with the checks above."""
        host = self.host
        if name not in host.names:
            return
        now = host.now_ns()
        if stamp > now + self.max_lead_ns:
            # after a reset sim time restarts at 0: a command answering a state from before the
            # reset carries a stamp ahead of the new sim time; it would also let lockstep skip
            # its waits up to that stamp
            host.warn("ahead", f"command for robot {name!r} stamped {stamp / 1e9:.3f} s, more than "
                      f"{self.max_lead_ns / 1e9:g} s ahead of sim time {now / 1e9:.3f} s "
                      f"(from before a reset?): dropped")
            return
        if not host.sim.command(wrench, name):
            host.warn("rejected", f"command rejected for robot {name!r} (non-finite or > 100 N/Nm): "
                      f"{np.array2string(np.asarray(wrench, float), precision=3)}")
            return
        # a command never answers a tick the sim has not reached: lockstep counts it for the
        # current tick at most (a slightly-ahead stamp must not let later ticks run unanswered),
        # and a stamp answers one tick only (repeats of one command arriving a tick apart, as
        # on a loaded machine, must not each let the sim step on)
        if stamp != self.raw_stamp[name]:
            self.raw_stamp[name] = stamp
            self.stamp[name] = max(self.stamp[name], min(stamp, now))
