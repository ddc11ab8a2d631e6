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
import signal
import sys
import threading
import time
from typing import Callable, Optional

from roszen.bag.writer import BagWriter
from roszen.qos import Durability, History, QoSProfile, Reliability

REDISCOVER_PERIOD = 1.0   # s between looks at the graph with no change event (a safety net)


def log(text: str) -> None:
    print(f"[INFO] [{time.time():.9f}] [rosbag2_recorder]: {text}", file=sys.stderr, flush=True)


def _say(text: str, timeout: float = 0.5) -> None:
    """log() from a thread about to exit the process: bounded (the main thread may hold
    stderr's lock, blocked in a write to a full pipe)."""
    t = threading.Thread(target=log, args=(text,), name="recorder-say", daemon=True)
    t.start()
    t.join(timeout)


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


class StopSignals:
    """SIGINT and SIGTERM for a recording process, served on a thread of their own.

    A Python signal handler runs on the main thread, and only between bytecodes: while that
    thread is inside a native call (zenoh's session close waits for a callback in flight, up
    to its own 10 s timeout; an undeclare; a put) no handler runs, and a handler that does run
    interrupts whatever frame is there (it must not wait on a lock that frame holds). A CI
    launch so ended with "'recorder' ignored SIGINT and SIGTERM: SIGKILL" after a good flight.
    Here the handlers do nothing; the signal number reaches `signal.set_wakeup_fd`'s pipe from
    the C-level handler whatever the main thread is doing, and a daemon thread reading it acts:

    - the first signal (SIGINT or SIGTERM) sets `stop`: the main thread ends the recording and
      completes the bag (Recorder.spin / finish), the normal, clean path;
    - any further one calls `on_second` (the recorder's stop_now: exit at once once the bag is
      complete, completing it from another thread if the main thread has not; bounded).

    Installed from the main thread for the rest of the process (its exit, where zenoh's
    session is closed, is covered too)."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self, on_second: Optional[Callable[[], None]] = None) -> None:
        self.stop = threading.Event()
        self.on_second = on_second or (lambda: os._exit(0))   # before a recorder exists
        self.count = 0
        self._r, w = os.pipe()
        os.set_blocking(w, False)
        signal.set_wakeup_fd(w, warn_on_full_buffer=False)     # from the main thread only
        for sig in self.SIGNALS:
            signal.signal(sig, _ignore)
        threading.Thread(target=self._watch, name="stop-signals", daemon=True).start()

    def _watch(self) -> None:
        while True:
            try:
                data = os.read(self._r, 64)
            except InterruptedError:
                continue
            if not data:
                return
            for signum in data:
                if signum in self.SIGNALS:
                    self.count += 1
                    if self.count == 1:
                        self.stop.set()
                    else:
                        self.on_second()


def _ignore(signum: int, frame) -> None:  # noqa: ARG001 - served by StopSignals' thread
    pass


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
        self._complete_lock = threading.Lock()
        self._done = threading.Event()   # the bag is finished (or failed for good): safe to exit
        self._meta = None
        self._error: BaseException | None = None
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

    def complete(self):
        """Finish the bag once (intake closed, what waits for a first /clock written, the writer's
        queue written, MCAP summary and footer, metadata.yaml) and return its metadata; raises
        BagError when a write failed. Any thread: the main thread's finish() or, after a second
        stop signal, StopSignals' (whichever comes first does it, the other gets its result)."""
        with self._complete_lock:
            if not self._done.is_set():
                self.intake = False
                try:
                    if self.sim is not None:
                        self.sim.flush_pending()
                    self._meta = self.writer.close()
                except BaseException as exc:    # noqa: BLE001 - handed to every caller
                    self._error = exc
                finally:
                    self._done.set()
        if self._error is not None:
            raise self._error
        return self._meta

    @property
    def completed(self) -> bool:
        """The bag is finished (footer, metadata.yaml) or failed for good: safe to exit."""
        return self._done.is_set()

    def exit_code(self) -> int:
        return 1 if self.failed.is_set() or self._error is not None else 0

    def finish(self, grace: float = 2.0, exit_code: int | None = None):
        """Stop recording and complete the bag, in an order that cannot lose its footer: the
        intake closes, the writer writes what it has and finishes the MCAP (summary, footer,
        metadata.yaml), and only then are the subscriptions undeclared, under a watchdog: a
        teardown that hangs (zenoh's undeclare, seen in 2 of ~14 launches at shutdown) ends
        the process after `grace` seconds with `exit_code` (default: exit_code()) instead of
        waiting for the launcher's SIGKILL. A second stop signal meanwhile: `stop_now()`.
        Returns the bag's metadata."""
        try:
            meta = self.complete()      # raises BagError when a write failed (a full disk)
        finally:
            code = self.exit_code() if exit_code is None else exit_code
            done = threading.Event()

            def watchdog() -> None:
                if not done.wait(grace):
                    log(f"the recorder's teardown hung for {grace:g} s after the bag was closed: exiting")
                    os._exit(code)
            threading.Thread(target=watchdog, name="recorder-teardown", daemon=True).start()
            try:
                self.close()
            finally:
                done.set()
        return meta

    def stop_now(self, grace: float = 2.0) -> None:
        """A second stop signal: end the process now, on the calling thread (StopSignals',
        never the main thread, which may be inside a zenoh call or holding the writer: a signal
        handler there cannot run, or would wait on what the interrupted frame holds).

        A complete bag: exit at once (exit_code()). Else the bag is completed on a thread of its
        own, or by the main thread already at it, for up to `grace` seconds; if it cannot be
        (the writer hangs), exit 1 with one line: what was flushed (every --flush-interval) is
        on disk and `bag reindex` rebuilds it. Never returns."""
        self.intake = False
        if not self._done.is_set():
            threading.Thread(target=self._complete_quietly, name="recorder-complete",
                             daemon=True).start()
        if self._done.wait(grace):
            os._exit(self.exit_code())
        where = self.writer.directory
        _say(f"error: the bag could not be completed within {grace:g} s of the second stop "
             f"signal: exiting; {where} holds what was flushed (astrobee bag reindex {where})")
        os._exit(1)

    def _complete_quietly(self) -> None:
        try:
            self.complete()
        except BaseException:   # noqa: BLE001 - the failure is the exit code (and the writer's line)
            pass

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
