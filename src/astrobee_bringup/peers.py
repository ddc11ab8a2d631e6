"""PeerWatch: which of the nodes and topics a client depends on have left the ROS graph.

The graph (roszen's cache of liveliness tokens) drops a node's tokens as soon as its process
dies or loses the router, killed with SIGKILL included, so a client can tell "the simulator is
gone" within a fraction of a second instead of waiting out a timeout; sim time cannot tell (the
clock stops with the simulator). A peer counts as lost only after it was seen once: a peer
that has not started yet is missing, not lost.

    watch = PeerWatch(node, nodes=["sim_node", "pd_controller_node"], topics=["/gnc/ekf"])
    ...
    watch.check()          # PeerLost("lost node sim_node") once the sim has gone
"""
from __future__ import annotations

from typing import Any, Iterable


class PeerLost(RuntimeError):
    """A required node or topic publisher that was in the graph has gone."""


def _node_matches(want: str, name: str, namespace: str) -> bool:
    """`want` is a bare node name (any namespace) or a fully qualified one (/ns/name)."""
    if "/" not in want:
        return want == name
    fqn = (namespace.rstrip("/") + "/" + name) if namespace != "/" else "/" + name
    return want == fqn


class PeerWatch:
    """Follows required nodes (by name) and topics (by their publishers) in `node`'s graph;
    needs no spinning (the graph is kept current by the transport's own threads)."""

    def __init__(self, node: Any, nodes: Iterable[str] = (), topics: Iterable[str] = ()) -> None:
        self.node = node
        self.nodes = [str(n) for n in nodes]
        self.topics = [node.resolve_topic_name(str(t)) for t in topics]
        self._seen: set[str] = set()
        self.update()

    def _present(self) -> dict[str, bool]:
        """Each peer's label ("node X" / "publisher of T") -> in the graph now."""
        graph = self.node.get_node_names_and_namespaces()
        out = {f"node {w.lstrip('/')}": any(_node_matches(w, n, ns) for n, ns in graph)
               for w in self.nodes}
        for t in self.topics:
            out[f"publisher of {t}"] = self.node.count_publishers(t) > 0
        return out

    def update(self) -> list[str]:
        """Look at the graph now; the lost peers (seen before, absent now), in order."""
        present = self._present()
        self._seen.update(k for k, here in present.items() if here)
        return [k for k, here in present.items() if not here and k in self._seen]

    def missing(self) -> list[str]:
        """Peers not in the graph now, whether seen before or not."""
        return [k for k, here in self._present().items() if not here]

    def lost(self) -> list[str]:
        """Peers that were in the graph and have gone."""
        return self.update()

    def check(self) -> None:
        """PeerLost naming every lost peer ("lost node sim_node"); nothing while all are there."""
        gone = self.update()
        if gone:
            raise PeerLost("lost " + ", ".join(gone))


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
