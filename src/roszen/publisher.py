"""Publisher: CDR samples with the rmw_zenoh attachment on a topic key expression."""
from __future__ import annotations

import itertools
from typing import TYPE_CHECKING, Any

import zenoh
import zenoh.ext as zext

from . import codec, wire
from .endpoint import _Endpoint
from .executor import _pending_interrupts, raise_pending
from .qos import QoSProfile
from .sigint import zenoh_callback

if TYPE_CHECKING:
    from .node import Node

_BLOCK, _DROP = zenoh.CongestionControl.BLOCK, zenoh.CongestionControl.DROP


class Publisher(_Endpoint):
    """Publishes CDR samples with the 33-byte rmw_zenoh attachment."""

    def __init__(self, node: "Node", msg_type: str, topic: str, qos: QoSProfile) -> None:
        sup = codec.msg_support(msg_type)
        self.msg_type = sup.name
        self.topic_name = node.resolve_topic_name(topic)
        self.qos_profile = qos
        self._init_endpoint(node, wire.PUB, self.topic_name, sup, qos)
        ctx = node.context
        self._seq = itertools.count(1)
        cc = _BLOCK if (qos.reliable and qos.keep_all) else _DROP
        rel = zenoh.Reliability.RELIABLE if qos.reliable else zenoh.Reliability.BEST_EFFORT
        if qos.transient_local:
            miss = zext.MissDetectionConfig(heartbeat=None, sporadic_heartbeat=0.5) if qos.reliable else None
            zpub = zext.declare_advanced_publisher(
                ctx.session, self.key_expr, congestion_control=cc, reliability=rel,
                cache=zext.CacheConfig(qos.effective_depth), sample_miss_detection=miss,
                publisher_detection=True)
        else:
            zpub = ctx.session.declare_publisher(self.key_expr, congestion_control=cc, reliability=rel)
        self._advertise(zpub)
        self._cls, self._serialize, self._put = sup.cls, sup.serialize, zpub.put
        self._attachment = wire.attachment_maker(self.gid)

    @zenoh_callback      # a SIGINT inside its put is raised after the put, not lost
    def publish(self, msg: Any) -> None:
        """Serialise and send; bytes are sent as an already serialised CDR payload."""
        if type(msg) is self._cls:
            data = self._serialize(msg)
        elif isinstance(msg, (bytes, bytearray, memoryview)):
            data = bytes(msg)
        elif isinstance(msg, self._cls):
            data = self._serialize(msg)
        else:
            raise TypeError(f"publisher on {self.topic_name} expects {self.msg_type}, got {type(msg).__name__}")
        self._put(data, attachment=self._attachment(next(self._seq)))
        if _pending_interrupts:  # Ctrl-C during a same-session subscriber's callback inside put
            raise_pending()

    def get_subscription_count(self) -> int:
        return self.node.context.graph.count_subscribers(self.topic_name)
