"""Whether a mission's command path is complete: relay_missing (is a safety filter relaying the
commands?). Peers that left the graph are roszen.peers' PeerWatch."""
from __future__ import annotations

from typing import Any


def relay_missing(node: Any, upstream: str, downstream: str) -> str:
    """Why no node relays `upstream` to `downstream` (subscribes one, publishes the other: a
    safety_filter_node) while `upstream` has publishers; "" when one does or none publishes.
    A mere subscriber does not count: the recorder subscribes every topic."""
    if node.count_publishers(upstream) == 0:
        return ""
    readers = {e.node_key for e in node.get_subscriptions_info_by_topic(upstream)}
    if any(e.node_key in readers for e in node.get_publishers_info_by_topic(downstream)):
        return ""
    return f"no node relaying {upstream} to {downstream} (a safety filter) yet"
