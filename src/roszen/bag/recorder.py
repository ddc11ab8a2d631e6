"""Bag recorder: subscribes (raw CDR) to topics found in the graph and hands samples to BagWriter.

New topics are picked up while recording (graph listener). Each subscription takes the QoS its
publishers offer (TRANSIENT_LOCAL only when every publisher is latched, BEST_EFFORT when one is)
with KEEP_ALL history so the node's queue never drops a sample; the writer thread does the rest.

With `use_sim_time` messages are stamped (MCAP log_time, what players pace by) with the sim
time of /clock when they are received, so a lockstep flight replays at its own pace; the
wall-clock receive time stays in publish_time. See SimStamp for the rules.
"""
from __future__ import annotations

import os
import re
import sys
import threading
import time

from roszen.bag.writer import BagWriter
from roszen.qos import Durability, History, QoSProfile, Reliability

REDISCOVER_PERIOD = 1.0   # s between looks at the graph with no change event (a safety net)


def log(text: str) -> None:
    print(f"[INFO] [{time.time():.9f}] [rosbag2_recorder]: {text}", file=sys.stderr, flush=True)


def subscription_qos(offered: list[QoSProfile]) -> QoSProfile:
    """The QoS a recorder subscribes with, given the publishers' offered profiles."""
    q = QoSProfile(depth=10, history=History.KEEP_ALL)
    if offered and all(o.durability == Durability.TRANSIENT_LOCAL for o in offered):
        q = q.with_(durability=Durability.TRANSIENT_LOCAL,
                    depth=max(o.effective_depth for o in offered))
    if any(o.reliability == Reliability.BEST_EFFORT for o in offered):
        q = q.with_(reliability=Reliability.BEST_EFFORT)
    return q


class SimStamp:
    """Receive times on the sim clock (/clock), for a recording on sim time.

    The bag's time axis never runs backwards: when /clock restarts (a sim reset between the
    legs of a demo) the stamps continue from the last one (the restart's 0 is the last stamp),
    and the reset is logged. Only one /clock publisher is followed (roszen.clock.ClockSource):
    another one's samples are ignored and logged once, so a stray clock (`bag play --clock` on
    a live graph) cannot interleave a second time line whose every step back would add a leg.
    Messages that arrive before the first /clock (latched ones) wait and get its time. If no
    /clock comes within `patience` wall seconds the recording falls back to wall-clock time."""

    def __init__(self, node, write, patience: float = 60.0, max_pending: int = 100_000):
        from roszen.clock import ClockSource
        from roszen.qos import CLOCK
        from roszen.subscription import Subscription
        self.write = write
        self._lock = threading.Lock()
        self.patience = patience
        self.max_pending = max_pending
        self.started = time.monotonic()
        self.offset = 0          # added to /clock: the shifts of every backwards jump
        self.last = None         # last /clock (ns), as received
        self.wall = False        # gave up waiting: stamps are wall-clock time
        self.pending: list = []  # (topic, data, wall ns) received before the first /clock
        # direct: the clock is read on arrival (zenoh's thread), as a node's own sim clock is, so
        # a message is never stamped with a /clock older than the one published before it
        self.source = ClockSource(node.context.graph, log=log)
        self.resets = 0
        self._sub = Subscription(node, "rosgraph_msgs/msg/Clock", "/clock", self._on_clock, CLOCK,
                                 direct=True, with_source=True)

    def _on_clock(self, msg, gid: bytes) -> None:
        if not self.source.accept(gid):
            return
        t = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
        with self._lock:
            if self.last is not None and t < self.last:   # restarted (from 0): continue
                self.offset += self.last
                self.resets += 1
                log(f"/clock went back from {self.last * 1e-9:.3f} s to {t * 1e-9:.3f} s (a sim reset): "
                    f"the bag's time continues from {self.offset * 1e-9:.3f} s")
            self.last = t
            if self.pending and not self.wall:
                now = self.last + self.offset
                for topic, data, wall in self.pending:
                    self.write(topic, data, now, wall)
                self.pending.clear()

    def now(self) -> int | None:
        """The bag time of a message received now (None: no /clock yet)."""
        return None if self.last is None else self.last + self.offset

    def stamp(self, topic: str, data: bytes) -> None:
        wall = time.time_ns()
        with self._lock:
            if self.wall:
                self.write(topic, data, wall, wall)
            elif self.last is None:
                self.pending.append((topic, data, wall))
            else:
                self.write(topic, data, self.last + self.offset, wall)
        if self.last is None:
            self.check()

    def check(self) -> None:
        """Fall back to wall time when /clock is overdue (or the wait would hold too much)."""
        with self._lock:
            if self.last is not None or self.wall or not (
                    time.monotonic() - self.started > self.patience
                    or len(self.pending) > self.max_pending):
                return
            self.wall = True
            for topic, data, wall in self.pending:
                self.write(topic, data, wall, wall)
            self.pending.clear()
        log(f"no /clock within {self.patience:g} s: recording with wall-clock time")

    def flush_pending(self) -> None:
        """Write what waits for a first /clock (never seen: on wall time)."""
        if self.pending:
            self.patience = -1.0
            self.check()

    def close(self) -> None:
        self.flush_pending()
        self._sub.destroy()


class Recorder:
    """Records `topics` (or all, minus hidden/excluded) of `node`'s graph into `writer`.

    `exclude` is a regular expression, `exclude_topics` exact names (`ros2 bag record
    --exclude-regex / --exclude-topics`); `use_sim_time` stamps with /clock (SimStamp)."""

    def __init__(self, node, writer: BagWriter, *, topics: list[str] | None = None,
                 regex: str | None = None, exclude: str | None = None,
                 include_hidden: bool = False, discovery: bool = True,
                 exclude_topics: list[str] | None = None, use_sim_time: bool = False):
        self.node = node
        self.writer = writer
        self.topics = set(topics or [])
        self.all = not topics and not regex
        self.regex = re.compile(regex) if regex else None
        self.exclude = re.compile(exclude) if exclude else None
        self.exclude_topics = set(exclude_topics or [])
        self.sim = SimStamp(node, writer.write) if use_sim_time else None
        self.failed = threading.Event()     # the writer failed (a full disk): recording ends
        writer.on_error = self._on_write_error
        self.include_hidden = include_hidden
        self.discovery = discovery
        self.subscriptions: dict[str, object] = {}
        self.received = 0
        self.intake = True       # False once stopping: samples still arriving are not written
        self.completed = False   # the bag is finished (footer, metadata.yaml): safe to exit
        self.hurry = False       # a second stop signal came: exit as soon as the bag is complete
        self._skipped: set[str] = set()
        self._probes: dict[str, dict] = {}     # topic -> {type: probe subscription} (several types)
        self._warned: set[str] = set()
        self._changed = threading.Event()
        self._changed.set()
        node.context.graph.add_listener(self._changed.set)

    def _on_write_error(self, exc: BaseException) -> None:
        """First failed write (writer thread): say so at once and end the recording."""
        self.intake = False
        log(f"error: writing the bag failed ({exc}); recording stopped after "
            f"{self.received} messages")
        self.failed.set()

    def wanted(self, topic: str) -> bool:
        if topic in self.exclude_topics or (self.exclude and self.exclude.search(topic)):
            return False
        if topic in self.topics:
            return True
        if self.regex and self.regex.search(topic):
            return True
        if self.all:
            hidden = any(p.startswith("_") for p in topic.split("/") if p)
            return self.include_hidden or not hidden
        return False

    def discover(self) -> None:
        """Subscribe to every wanted topic that now has a publisher.

        A liveliness token is only a claim: a peer may advertise a known topic with another
        type. Publishers whose advertised type hash is not the hash of their advertised type
        (or whose type is unknown) are ignored with a warning. If valid publishers still offer
        several types, each type is subscribed and the first to deliver a sample is recorded
        (a bag holds one type per topic); the others are dropped with a warning. A mere token
        can so never hide the real publisher's data.
        """
        for topic, _types in self.node.get_topic_names_and_types():
            if topic in self.subscriptions or topic in self._skipped or not self.wanted(topic):
                continue
            pubs = [e for e in self.node.get_publishers_info_by_topic(topic)
                    if e.node_name != self.node.get_name()]
            if not pubs:
                continue
            candidates = self._valid_types(topic, pubs)
            if not candidates:
                continue
            if len(candidates) == 1:
                type_name, (msgdef, type_hash) = next(iter(candidates.items()))
                self._record(topic, type_name, msgdef, type_hash,
                             [e.qos for e in pubs if e.ros_type == type_name])
                continue
            if topic in self._probes:
                continue
            log(f"topic '{topic}' is advertised with several types ({', '.join(candidates)}): "
                f"recording the first that delivers a message")
            self._probes[topic] = {
                type_name: self.node.create_subscription(
                    type_name, topic, self._probe_callback(topic, type_name, msgdef, type_hash, pubs),
                    subscription_qos([e.qos for e in pubs if e.ros_type == type_name]), raw=True)
                for type_name, (msgdef, type_hash) in candidates.items()}

    def _valid_types(self, topic: str, pubs: list) -> dict:
        """{type: (definition, hash)} of the publishers whose advertised hash matches their type."""
        from roszen import typestore
        out: dict = {}
        for e in pubs:
            try:
                msgdef = typestore.message_definition(e.ros_type)
                expected = typestore.type_hash(e.ros_type)
            except (typestore.UnknownTypeError, ValueError) as exc:
                self._warn_once(e.token, f"ignoring a publisher of '{topic}' from node {e.node_fqn}: "
                                         f"type {e.ros_type} unknown ({exc})")
                continue
            if e.type_hash and e.type_hash != expected:
                self._warn_once(e.token, f"ignoring a publisher of '{topic}' from node {e.node_fqn}: it "
                                         f"advertises {e.ros_type} with type hash {e.type_hash}, which "
                                         f"is not that type's hash {expected}")
                continue
            out.setdefault(e.ros_type, (msgdef, expected))
        return out

    def _warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            log(text)

    def _record(self, topic: str, type_name: str, msgdef: str, type_hash: str, offered: list) -> None:
        self.writer.add_topic(topic, type_name, msgdef, type_hash, offered)
        self.subscriptions[topic] = self.node.create_subscription(
            type_name, topic, self._callback(topic), subscription_qos(offered), raw=True)
        log(f"Subscribed to topic '{topic}'")

    def _probe_callback(self, topic: str, type_name: str, msgdef: str, type_hash: str, pubs: list):
        """First sample of one candidate type: that type is recorded, the other probes end."""
        won = []
        write = self._callback(topic)

        def on_sample(data: bytes) -> None:
            if won:
                write(data)
                return
            probes = self._probes.get(topic)
            if probes is None or topic in self.subscriptions:
                return   # another type won (samples already queued for this probe)
            won.append(True)
            offered = [e.qos for e in pubs if e.ros_type == type_name]
            self.writer.add_topic(topic, type_name, msgdef, type_hash, offered)
            self.subscriptions[topic] = probes.pop(type_name)
            for other, sub in probes.items():
                self.node.destroy_subscription(sub)
                log(f"topic '{topic}': recording {type_name}; no message came as {other}, "
                    f"whose publisher advertises a type the data does not have")
            del self._probes[topic]
            log(f"Subscribed to topic '{topic}'")
            write(data)
        return on_sample

    def _callback(self, topic: str):
        write = self.writer.write
        sim = self.sim

        def on_sample(data: bytes) -> None:
            if not self.intake:
                return
            if sim is None:
                write(topic, data, time.time_ns())
            else:
                sim.stamp(topic, data)
            self.received += 1
        return on_sample

    def spin(self, stop: threading.Event) -> None:
        """Record until `stop` is set."""
        # cleared before the look, never after: a topic appearing during discover() sets the
        # event again and is picked up at the next turn (clearing after lost it until the next
        # graph change: a CI run's recorder missed every sim topic for 89 s)
        self._changed.clear()
        self.discover()
        log("Recording...")
        if self.topics:
            missing = sorted(self.topics - set(self.subscriptions))
            if missing:
                log(f"Waiting for topics to appear: {', '.join(missing)}")
        next_look = time.monotonic() + REDISCOVER_PERIOD
        while not stop.is_set() and not self.failed.is_set():
            self.node.spin_once(timeout_sec=0.05)
            # on every graph change, and once a second besides (a missed event costs a second)
            if self.discovery and (self._changed.is_set() or time.monotonic() > next_look):
                self._changed.clear()
                next_look = time.monotonic() + REDISCOVER_PERIOD
                self.discover()
            if self.sim is not None:
                self.sim.check()
        # samples already received but not yet dispatched belong in the bag (bounded: 2 s)
        end = time.monotonic() + 2.0
        while time.monotonic() < end and self.node.spin_once(timeout_sec=0):
            pass

    def finish(self, grace: float = 2.0, exit_code: int = 0):
        """Stop recording and complete the bag, in an order that cannot lose its footer: the
        intake closes, the writer writes what it has and finishes the MCAP (summary, footer,
        metadata.yaml), and only then are the subscriptions undeclared, under a watchdog: a
        teardown that hangs (zenoh's undeclare, seen in 2 of ~14 launches at shutdown) ends
        the process after `grace` seconds with `exit_code` instead of ignoring SIGINT/SIGTERM
        until a SIGKILL cuts the file. `stop_signal()` is for a signal arriving meanwhile.
        Returns the bag's metadata."""
        self.intake = False
        if self.sim is not None:
            self.sim.flush_pending()
        try:
            meta = self.writer.close()      # raises BagError when a write failed (a full disk)
        finally:
            self.completed = True
            if self.hurry:
                log("stopping at once (second stop signal)")
                os._exit(exit_code)
            done = threading.Event()

            def watchdog() -> None:
                if not done.wait(grace):
                    log(f"the recorder's teardown hung for {grace:g} s after the bag was closed: exiting")
                    os._exit(exit_code)
            threading.Thread(target=watchdog, name="recorder-teardown", daemon=True).start()
            try:
                self.close()
            finally:
                done.set()
        return meta

    def stop_signal(self) -> None:
        """A stop signal during finish(): exit now if the bag is complete, else once it is."""
        self.hurry = True
        if self.completed:
            os._exit(0)

    def close(self) -> None:
        self.intake = False
        self.node.context.graph.remove_listener(self._changed.set)
        if self.sim is not None:
            self.sim.close()
        for sub in self.subscriptions.values():
            self.node.destroy_subscription(sub)
        for probes in self._probes.values():
            for sub in probes.values():
                self.node.destroy_subscription(sub)
        self._probes.clear()
