"""Graph cache: every node/endpoint of the domain, kept current from liveliness tokens."""
from __future__ import annotations

import threading
import time
from collections import defaultdict
from typing import Callable, Optional

import zenoh

from .sigint import zenoh_callback
from .wire import ADMIN_SPACE, CLIENT, NODE, PUB, SERVICE, SUB, parse_token


class GraphCache:
    """Liveliness `get` at start plus a liveliness subscriber; answers ros2-style graph queries."""

    def __init__(self, session: "zenoh.Session", domain_id: int, logger=None) -> None:
        self._session = session
        self.domain_id = domain_id
        self._log = logger
        self._entities: dict = {}
        self._cond = threading.Condition()
        self._ready = threading.Event()
        self._listeners: list = []
        self._bad_tokens: set = set()
        key = f"{ADMIN_SPACE}/{domain_id}/**"
        lv = session.liveliness()
        self._sub = lv.declare_subscriber(key, zenoh.handlers.Callback(self._on_sample, indirect=False),
                                         history=True)
        # the replies through zenoh's own channel, drained by a thread: a Python callback would
        # be dropped on zenoh's thread under the session's lock when the query ends, taking the
        # GIL there, and a node undeclaring an entity meanwhile (holding the GIL, waiting for
        # that lock) deadlocked (a hung fresh-clone run, tests/runtime/test_bad_input.py)
        replies = lv.get(key, timeout=3.0)
        threading.Thread(target=self._drain, args=(replies,), name="roszen-graph-get",
                         daemon=True).start()

    def _drain(self, replies) -> None:
        try:
            for reply in replies:
                self._on_reply(reply)
        finally:
            self._ready.set()

    # -- updates ----------------------------------------------------------------------------
    @zenoh_callback
    def _on_sample(self, sample: "zenoh.Sample") -> None:
        token = str(sample.key_expr)
        if sample.kind == zenoh.SampleKind.DELETE:
            self.remove(token)
        else:
            self.add(token)

    @zenoh_callback
    def _on_reply(self, reply: "zenoh.Reply") -> None:
        if reply.ok is not None:
            self.add(str(reply.ok.key_expr))

    def add(self, token: str) -> None:
        if token in self._entities:
            return
        try:
            ent = parse_token(token)
        except (ValueError, IndexError) as e:
            if token not in self._bad_tokens and self._log is not None:
                self._bad_tokens.add(token)
                self._log.warn(f"ignoring malformed liveliness token {token!r}: {e}")
            return
        with self._cond:
            self._entities[token] = ent
            self._cond.notify_all()
        self._notify()

    def remove(self, token: str) -> None:
        with self._cond:
            if self._entities.pop(token, None) is None:
                return
            self._cond.notify_all()
        self._notify()

    def _notify(self) -> None:
        for cb in list(self._listeners):
            try:
                cb()
            except Exception:
                pass

    def add_listener(self, cb: Callable[[], None]) -> None:
        self._listeners.append(cb)

    def remove_listener(self, cb: Callable[[], None]) -> None:
        try:
            self._listeners.remove(cb)
        except ValueError:
            pass

    def wait_ready(self, timeout: float = 3.0) -> bool:
        """Wait for the initial liveliness query to complete."""
        return self._ready.wait(timeout)

    def wait_for(self, predicate: Callable[[], bool], timeout: Optional[float]) -> bool:
        """Block until predicate() is true after a graph change, or the timeout passes."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cond:
            while not predicate():
                rem = None if deadline is None else deadline - time.monotonic()
                if rem is not None and rem <= 0:
                    return False
                self._cond.wait(0.25 if rem is None else min(rem, 0.25))
            return True

    def close(self) -> None:
        try:
            self._sub.undeclare()
        except Exception:
            pass

    # -- queries ------------------------------------------------------------------------------
    def entities(self, kind: Optional[str] = None) -> list:
        """A snapshot of the graph's entities (zenoh's liveliness thread adds and removes them
        while a query iterates: every query reads this copy, taken under the writers' lock)."""
        with self._cond:
            ents = list(self._entities.values())
        return ents if kind is None else [e for e in ents if e.kind == kind]

    def get_node_names_and_namespaces(self) -> list:
        seen = {}
        for e in self.entities(NODE):
            seen[(e.zid, e.nid)] = (e.node_name, e.namespace)
        return sorted(set(seen.values()), key=lambda t: (t[1], t[0]))

    def get_node_names_and_namespaces_with_enclaves(self) -> list:
        return sorted({(e.node_name, e.namespace, e.enclave) for e in self.entities(NODE)})

    def get_node_names(self) -> list:
        return [n for n, _ in self.get_node_names_and_namespaces()]

    def _names_and_types(self, kinds: tuple, node: Optional[tuple] = None) -> list:
        out: dict = defaultdict(set)
        for e in self.entities():
            if e.kind in kinds and (node is None or (e.node_name, e.namespace) == node):
                out[e.name].add(e.ros_type)
        return sorted((k, sorted(v)) for k, v in out.items())

    def get_topic_names_and_types(self) -> list:
        """[(topic, [types])] over publishers and subscriptions."""
        return self._names_and_types((PUB, SUB))

    def get_service_names_and_types(self) -> list:
        """[(service, [types])] over servers and clients (like rmw_zenoh)."""
        return self._names_and_types((SERVICE, CLIENT))

    def get_publisher_names_and_types_by_node(self, node_name: str, namespace: str) -> list:
        return self._names_and_types((PUB,), (node_name, namespace))

    def get_subscriber_names_and_types_by_node(self, node_name: str, namespace: str) -> list:
        return self._names_and_types((SUB,), (node_name, namespace))

    def get_service_names_and_types_by_node(self, node_name: str, namespace: str) -> list:
        return self._names_and_types((SERVICE,), (node_name, namespace))

    def get_client_names_and_types_by_node(self, node_name: str, namespace: str) -> list:
        return self._names_and_types((CLIENT,), (node_name, namespace))

    def _count(self, kind: str, name: str) -> int:
        return sum(1 for e in self.entities(kind) if e.name == name)

    def count_publishers(self, topic: str) -> int:
        return self._count(PUB, topic)

    def count_subscribers(self, topic: str) -> int:
        return self._count(SUB, topic)

    def count_services(self, name: str) -> int:
        return self._count(SERVICE, name)

    def count_clients(self, name: str) -> int:
        return self._count(CLIENT, name)

    def get_publishers_info_by_topic(self, topic: str) -> list:
        """Endpoint entities (node, type, hash, QoS, gid) of the topic's publishers."""
        return sorted((e for e in self.entities(PUB) if e.name == topic), key=lambda e: e.token)

    def get_subscriptions_info_by_topic(self, topic: str) -> list:
        return sorted((e for e in self.entities(SUB) if e.name == topic), key=lambda e: e.token)

    def service_is_available(self, name: str, dds_type: Optional[str] = None,
                             type_hash: Optional[str] = None) -> bool:
        for e in self.entities(SERVICE):
            if e.kind == SERVICE and e.name == name and (dds_type is None or e.dds_type == dds_type) \
                    and (type_hash is None or e.type_hash == type_hash):
                return True
        return False
