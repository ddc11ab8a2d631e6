"""Peers leaving the ROS graph: PeerWatch (required nodes and topics) and PublisherWatch (the
publishers of one topic, named, and whether their node left or only stopped publishing).

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

import time
from dataclasses import dataclass
from typing import Any, Iterable, Optional

TOKEN_SETTLE = 0.3      # wall s a dead node may keep its node token after its topics' went


class PeerLost(RuntimeError):
    """A required node or topic publisher that was in the graph has gone."""


def _fqn(name: str, namespace: str) -> str:
    return (namespace.rstrip("/") + "/" + name) if namespace not in ("", "/") else "/" + name


def _node_matches(want: str, name: str, namespace: str) -> bool:
    """`want` is a bare node name (any namespace) or a fully qualified one (/ns/name)."""
    if "/" not in want:
        return want == name
    return want == _fqn(name, namespace)


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


@dataclass(frozen=True)
class PublisherLoss:
    """The topic has no publisher left: `node_left` when their nodes left the graph too (a
    lost node), else they only stopped publishing it; `who` names them; `pending` while a
    publisher's node is still in the graph but may be leaving (not yet `settle` s)."""
    node_left: bool
    who: str
    pending: bool = False


class PublisherWatch:
    """The publishers of one topic (other nodes than `node`), remembered while there are any so
    a loss names them; `loss()` tells a node that left the graph from one that stopped
    publishing (waiting `settle` wall s: a dead process's tokens leave one by one)."""

    def __init__(self, node: Any, topic: str, settle: float = TOKEN_SETTLE) -> None:
        self.node = node
        self.topic = node.resolve_topic_name(topic)
        self.settle = settle
        self.names: list[str] = []          # fully qualified names of the last publishers seen
        self._unpublished_since: Optional[float] = None

    @property
    def who(self) -> str:
        """The last publishers seen, for messages ("sim_node"), or "its publisher"."""
        return ", ".join(n.lstrip("/") for n in self.names) or "its publisher"

    def publishers(self) -> list[str]:
        """The topic's publishers now, remembered (with the loss timer reset) when any."""
        me = self.node.get_fully_qualified_name()
        pubs = sorted({e.node_fqn for e in self.node.get_publishers_info_by_topic(self.topic)
                       if e.node_fqn != me})
        if pubs:
            self.names = pubs
            self._unpublished_since = None
        return pubs

    def loss(self) -> Optional[PublisherLoss]:
        """None while the topic has publishers; else the loss (`pending` while undecided)."""
        if self.publishers():
            return None
        alive = {_fqn(n, ns) for n, ns in self.node.get_node_names_and_namespaces()}
        now = time.monotonic()
        if self._unpublished_since is None:
            self._unpublished_since = now
        publisher_alive = any(p in alive for p in self.names)
        pending = publisher_alive and now - self._unpublished_since < self.settle
        return PublisherLoss(node_left=not publisher_alive, who=self.who, pending=pending)
