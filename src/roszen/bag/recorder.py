"""Bag recorder: subscribes (raw CDR) to topics found in the graph and hands samples to BagWriter.

New topics are picked up while recording (graph listener). Each subscription takes the QoS its
publishers offer (TRANSIENT_LOCAL only when every publisher is latched, BEST_EFFORT when one is)
with KEEP_ALL history so the node's queue never drops a sample; the writer thread does the rest.
"""
from __future__ import annotations

import re
import sys
import threading
import time

from roszen.bag.writer import BagWriter
from roszen.qos import Durability, History, QoSProfile, Reliability


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


class Recorder:
    """Records `topics` (or all, minus hidden/excluded) of `node`'s graph into `writer`."""

    def __init__(self, node, writer: BagWriter, *, topics: list[str] | None = None,
                 regex: str | None = None, exclude: str | None = None,
                 include_hidden: bool = False, discovery: bool = True):
        self.node = node
        self.writer = writer
        self.topics = set(topics or [])
        self.all = not topics and not regex
        self.regex = re.compile(regex) if regex else None
        self.exclude = re.compile(exclude) if exclude else None
        self.include_hidden = include_hidden
        self.discovery = discovery
        self.subscriptions: dict[str, object] = {}
        self.received = 0
        self._skipped: set[str] = set()
        self._changed = threading.Event()
        self._changed.set()
        node.context.graph.add_listener(self._changed.set)

    def wanted(self, topic: str) -> bool:
        if self.exclude and self.exclude.search(topic):
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
        """Subscribe to every wanted topic that now has a publisher."""
        from roszen import typestore
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self.subscriptions or topic in self._skipped or not self.wanted(topic):
                continue
            pubs = [e for e in self.node.get_publishers_info_by_topic(topic)
                    if e.node_name != self.node.get_name()]
            if not pubs:
                continue
            type_name = pubs[0].ros_type
            if len({e.ros_type for e in pubs}) > 1:
                log(f"topic '{topic}' has several types ({', '.join(types)}): recording "
                    f"{type_name} only")
            try:
                msgdef = typestore.message_definition(type_name)
                type_hash = pubs[0].type_hash or typestore.type_hash(type_name)
            except (typestore.UnknownTypeError, ValueError) as exc:
                self._skipped.add(topic)
                log(f"skipping topic '{topic}': type {type_name} unknown ({exc})")
                continue
            offered = [e.qos for e in pubs if e.ros_type == type_name]
            self.writer.add_topic(topic, type_name, msgdef, type_hash, offered)
            self.subscriptions[topic] = self.node.create_subscription(
                type_name, topic, self._callback(topic), subscription_qos(offered), raw=True)
            log(f"Subscribed to topic '{topic}'")

    def _callback(self, topic: str):
        write = self.writer.write

        def on_sample(data: bytes) -> None:
            write(topic, data, time.time_ns())
            self.received += 1
        return on_sample

    def spin(self, stop: threading.Event) -> None:
        """Record until `stop` is set."""
        self.discover()
        self._changed.clear()
        log("Recording...")
        if self.topics:
            missing = sorted(self.topics - set(self.subscriptions))
            if missing:
                log(f"Waiting for topics to appear: {', '.join(missing)}")
        while not stop.is_set():
            self.node.spin_once(timeout_sec=0.05)
            if self.discovery and self._changed.is_set():
                self._changed.clear()
                self.discover()
        # samples already received but not yet dispatched belong in the bag (bounded: 2 s)
        end = time.monotonic() + 2.0
        while time.monotonic() < end and self.node.spin_once(timeout_sec=0):
            pass

    def close(self) -> None:
        self.node.context.graph.remove_listener(self._changed.set)
        for sub in self.subscriptions.values():
            self.node.destroy_subscription(sub)
