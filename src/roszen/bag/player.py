"""Bag player: republishes recorded CDR with the recorded timing (scaled by rate) and QoS.

Latched topics (TRANSIENT_LOCAL offered QoS) are republished latched, so late subscribers get
them. With `clock_hz` the player publishes /clock (rosgraph_msgs/Clock) at that rate with the
bag's time, for nodes running with use_sim_time; it is then the only time base on /clock: a
/clock recorded in the bag is not republished (a bag recorded on sim time has the sim time as
its time axis, so the player's clock is that sim time).
"""
from __future__ import annotations

import sys
import threading
import time

from roszen.bag.metadata import BagError
from roszen.bag.reader import BagReader
from roszen.qos import Durability, QoSProfile, Reliability


def log(text: str) -> None:
    print(f"[INFO] [{time.time():.9f}] [rosbag2_player]: {text}", file=sys.stderr, flush=True)


def publisher_qos(offered: list[QoSProfile]) -> QoSProfile:
    """The QoS to republish a topic with, from its recorded offered profiles."""
    if not offered:
        return QoSProfile(depth=10)
    q = QoSProfile(depth=max(10, max(o.effective_depth for o in offered)))
    if any(o.durability == Durability.TRANSIENT_LOCAL for o in offered):
        q = q.with_(durability=Durability.TRANSIENT_LOCAL,
                    depth=max(o.effective_depth for o in offered
                              if o.durability == Durability.TRANSIENT_LOCAL))
    if all(o.reliability == Reliability.BEST_EFFORT for o in offered):
        q = q.with_(reliability=Reliability.BEST_EFFORT)
    return q


class Player:
    """Plays one bag directory on `node`'s graph."""

    def __init__(self, node, reader: BagReader, *, rate: float = 1.0, loop: bool = False,
                 topics: list[str] | None = None, clock_hz: float = 0.0,
                 start_offset: float = 0.0, delay: float = 0.0, settle: float = 0.3,
                 exclude_topics: list[str] | None = None, exclude_regex: str | None = None):
        if not rate > 0:
            raise BagError(f"rate must be > 0, got {rate}")
        self.node = node
        self.reader = reader
        self.rate = rate
        self.loop = loop
        self.clock_hz = clock_hz
        self.start_offset_ns = int(start_offset * 1e9)
        self.delay = delay
        self.settle = settle
        self.meta = reader.metadata()
        known = {t.name: t for t in self.meta.topics}
        if topics:
            missing = [t for t in topics if t not in known]
            if missing:
                raise BagError(f"topic '{missing[0]}' is not in the bag "
                               f"(has: {', '.join(sorted(known)) or 'none'})")
        import re
        rx = re.compile(exclude_regex) if exclude_regex else None
        skip = set(exclude_topics or [])
        self.topics = [t for t in (topics or list(known))
                       if t not in skip and not (rx and rx.search(t))]
        if clock_hz > 0 and "/clock" in self.topics:
            self.topics.remove("/clock")     # one time base on /clock: the player's
            log("not republishing the recorded /clock: --clock publishes the bag's time")
        self.publishers: dict[str, object] = {}
        self.published = 0

    def _make_publishers(self) -> None:
        from roszen import typestore
        for t in self.meta.topics:
            if t.name not in self.topics:
                continue
            try:
                typestore.get_spec(typestore.normalize_type_name(t.type))
            except (typestore.UnknownTypeError, ValueError) as exc:
                log(f"skipping topic '{t.name}': type {t.type} unknown ({exc})")
                continue
            self.publishers[t.name] = self.node.create_publisher(
                t.type, t.name, publisher_qos(t.offered_qos))

    def play(self, stop: threading.Event) -> None:
        """Publish until the bag ends (or forever with loop) or `stop` is set."""
        self._make_publishers()
        clock_pub = None
        if self.clock_hz > 0:
            from roszen.qos import CLOCK
            clock_pub = self.node.create_publisher("rosgraph_msgs/msg/Clock", "/clock", CLOCK)
            from roszen import typestore
            Clock = typestore.message_class("rosgraph_msgs/msg/Clock")
        wait = self.settle + self.delay
        if wait > 0:
            self._sleep_until(time.monotonic() + wait, stop)
        log(f"Set rate to {self.rate:g}")
        log("Playback until the end of the bag" + (" (looping)" if self.loop else ""))
        bag_start = self.meta.start_ns + self.start_offset_ns
        while not stop.is_set():
            wall0 = time.monotonic()
            next_clock = wall0
            for m in self.reader.messages(self.topics):
                if stop.is_set():
                    break
                if m.log_time_ns < bag_start:
                    continue
                pub = self.publishers.get(m.topic.name)
                if pub is None:
                    continue
                due = wall0 + (m.log_time_ns - bag_start) / 1e9 / self.rate
                while clock_pub is not None and next_clock <= due and not stop.is_set():
                    self._sleep_until(next_clock, stop)
                    now_bag = bag_start + int((time.monotonic() - wall0) * self.rate * 1e9)
                    c = Clock()
                    c.clock.sec, c.clock.nanosec = divmod(now_bag, 1_000_000_000)
                    clock_pub.publish(c)
                    next_clock += 1.0 / self.clock_hz
                self._sleep_until(due, stop)
                if stop.is_set():
                    break
                pub.publish(m.data)
                self.published += 1
            if not self.loop:
                break
        self._sleep_until(time.monotonic() + 0.2, stop)

    def _sleep_until(self, t: float, stop: threading.Event) -> None:
        while not stop.is_set():
            left = t - time.monotonic()
            if left <= 0:
                return
            if left > 0.002:
                stop.wait(left - 0.001)
            # the last millisecond: yield without oversleeping
            elif left > 0:
                time.sleep(0)
