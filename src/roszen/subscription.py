"""Subscription: samples buffered on the zenoh thread, decoded and handled on the executor."""
from __future__ import annotations

import collections
import traceback
from typing import TYPE_CHECKING, Callable, Optional

import zenoh
import zenoh.ext as zext

from . import codec, wire
from .endpoint import _callback, _Endpoint, _Entity, _max_bytes_default, _reraise_on_main
from .qos import QoSProfile
from .sigint import zenoh_callback

if TYPE_CHECKING:
    from .node import Node


class Subscription(_Entity, _Endpoint):
    """Receives samples into a per-subscription buffer bounded like a DDS history."""

    def __init__(self, node: "Node", msg_type: str, topic: str, callback: Callable, qos: QoSProfile,
                 raw: bool = False, direct: bool = False, max_bytes: Optional[int] = None,
                 with_source: bool = False) -> None:
        sup = codec.msg_support(msg_type)
        self.msg_type = sup.name
        self.topic_name = node.resolve_topic_name(topic)
        self.qos_profile = qos
        self.callback = callback
        self.raw = raw
        self._direct = direct
        self._with_source = with_source   # callback(msg, publisher GID): the /clock source policy
        self._deserialize = sup.deserialize
        self._buf: collections.deque = collections.deque(maxlen=None if qos.keep_all else qos.effective_depth)
        self.max_bytes = max_bytes if max_bytes is not None else _max_bytes_default()
        self._warned: set = set()
        self.dropped = 0
        self._init_endpoint(node, wire.SUB, self.topic_name, sup, qos)
        ctx = node.context
        # indirect: zenoh's network thread only hands the sample to a zenoh-python thread, so it
        # never waits for the GIL while the executor decodes (x2 msgs/s measured, same latency)
        on_sample = (_callback(self._on_sample_direct) if direct
                     else zenoh.handlers.Callback(self._on_sample, indirect=True))
        if qos.transient_local:
            zsub = zext.declare_advanced_subscriber(
                ctx.session, self.key_expr, on_sample,
                history=zext.HistoryConfig(detect_late_publishers=True, max_samples=qos.effective_depth),
                recovery=zext.RecoveryConfig(periodic_queries=None, heartbeat=True) if qos.reliable else None,
                subscriber_detection=True)
        else:
            zsub = ctx.session.declare_subscriber(self.key_expr, on_sample)
        self._advertise(zsub)

    def _on_sample(self, sample: "zenoh.Sample") -> None:  # zenoh thread: the minimum
        if len(sample.payload) > self.max_bytes:  # never buffered: a flood of huge samples costs no memory
            self._drop_once("oversize", f"larger than this subscription's limit of {self.max_bytes} bytes "
                                        f"({len(sample.payload)} bytes)")
            return
        self._buf.append(sample)
        if not self._scheduled:
            self.node._executor.schedule(self)

    @zenoh_callback
    def _on_sample_direct(self, sample: "zenoh.Sample") -> None:  # zenoh thread (/clock only)
        try:
            if len(sample.payload) > self.max_bytes:
                self._drop_once("oversize", f"larger than this subscription's limit of {self.max_bytes} "
                                            f"bytes ({len(sample.payload)} bytes)")
                return
            self._execute(sample)
            self.node._executor.wake()
        except (KeyboardInterrupt, SystemExit) as e:  # may run on the main thread inside a put
            _reraise_on_main(e)

    def _drop_once(self, why: str, what: str) -> None:
        """Count a dropped sample; log the first of each kind per subscription (a flood logs once)."""
        self.dropped += 1
        if why not in self._warned:
            self._warned.add(why)
            self.node.get_logger().warn(
                f"dropping samples on {self.topic_name} {what}; further ones are dropped silently")

    def _execute(self, sample: "zenoh.Sample") -> None:
        """Decode one sample and run the callback (executor thread; zenoh thread for /clock)."""
        att = sample.attachment
        if att is None:
            self._drop_once("no_att", "without the rmw_zenoh attachment (as rmw_zenoh does)")
            return
        ab = att.to_bytes()
        if len(ab) != wire.ATTACHMENT_SIZE or ab[16] != 16:
            self._drop_once("bad_att", f"with a malformed rmw_zenoh attachment ({len(ab)} bytes, expected "
                                       f"{wire.ATTACHMENT_SIZE}: seq, timestamp, 0x10, 16-byte GID)")
            return
        data = sample.payload.to_bytes()
        if self.raw:
            msg = data
        else:
            try:
                msg = self._deserialize(data)
            except Exception as e:
                self._report_bad(ab, f"malformed CDR payload ({len(data)} bytes) for {self.msg_type}: {e}")
                return
        try:
            if self._with_source:
                self.callback(msg, ab[17:])
            else:
                self.callback(msg)
        except Exception:
            self.node.get_logger().error(
                f"subscription callback for {self.topic_name} raised:\n{traceback.format_exc().rstrip()}")

    def _report_bad(self, att: bytes, what: str) -> None:
        self.dropped += 1
        src = att[17:].hex()
        self.node.get_logger().error(f"dropped a sample on {self.topic_name} from {src}: {what}")

    def get_publisher_count(self) -> int:
        return self.node.context.graph.count_publishers(self.topic_name)
