"""The hidden helper node of the `astrobee` verbs (topic, service, param, bag play) on real rclpy:
roszen's verb code runs unchanged over it (roszen.cli.common.make_node hands it out when
ASTROBEE_RUNTIME=rclpy); only what roszen reads from its Zenoh graph cache is given here, from
rclpy's graph queries (DDS discovery has no event the verbs can wait on, so they poll)."""
from __future__ import annotations

import time
from types import SimpleNamespace
from typing import Any, Callable

from .node import Node

POLL = 0.05                 # s between looks at rclpy's graph
SETTLE_QUIET = 0.4          # s without a graph change: discovery of what exists has settled
SETTLE_LIMIT = 5.0          # s at most spent on that at start (a remote node seen after
                            # 0.01-1.6 s here; once not within 3 s in a test run)


class PolledGraph:
    """What the verbs use of roszen's `node.context.graph`, over rclpy's graph queries."""

    def __init__(self, node: "CliNode") -> None:
        self._node = node

    def snapshot(self) -> tuple:
        n = self._node
        return (tuple(sorted(n.get_node_names_and_namespaces())),
                tuple((t, tuple(ts)) for t, ts in n.get_topic_names_and_types()),
                tuple((s, tuple(ts)) for s, ts in n.get_service_names_and_types()))

    def wait_ready(self, timeout: float = SETTLE_LIMIT, quiet: float = SETTLE_QUIET) -> bool:
        """Wait until another node is seen and the graph then stops changing for `quiet` s
        (bounded by `timeout`: an empty graph costs that much); whether it settled."""
        end = time.monotonic() + timeout
        last, since = self.snapshot(), time.monotonic()
        while time.monotonic() < end:
            time.sleep(POLL)
            now = self.snapshot()
            if now != last:
                last, since = now, time.monotonic()
            elif len(now[0]) > 1 and time.monotonic() - since >= quiet:
                return True
        return False

    def wait_for(self, cond: Callable[[], bool], timeout: float) -> bool:
        """Poll `cond` until true or `timeout` s passed."""
        end = time.monotonic() + timeout
        while not cond():
            if time.monotonic() >= end:
                return False
            time.sleep(POLL)
        return True

    def entities(self, kind: Any) -> list:
        """Servers (name, ros_type) for roszen.wire.SERVICE; publishers otherwise."""
        from ..wire import SERVICE
        n = self._node
        pairs = n.get_service_names_and_types() if kind == SERVICE else \
            n.get_topic_names_and_types()
        return [SimpleNamespace(name=name, ros_type=t) for name, types in pairs for t in types]

    # `node info`: rclpy's per-node queries, [(name, [types])]
    def get_subscriber_names_and_types_by_node(self, name: str, ns: str) -> list:
        return self._node._rnode.get_subscriber_names_and_types_by_node(name, ns)

    def get_publisher_names_and_types_by_node(self, name: str, ns: str) -> list:
        return self._node._rnode.get_publisher_names_and_types_by_node(name, ns)

    def get_service_names_and_types_by_node(self, name: str, ns: str) -> list:
        return self._node._rnode.get_service_names_and_types_by_node(name, ns)

    def get_client_names_and_types_by_node(self, name: str, ns: str) -> list:
        return self._node._rnode.get_client_names_and_types_by_node(name, ns)

    # the Recorder registers a change listener; none come here (it looks again periodically)
    def add_listener(self, cb: Any) -> None:
        pass

    def remove_listener(self, cb: Any) -> None:
        pass


class CliNode(Node):
    """An rclpy-backed Node for one command: no parameter services, no rosout; Ctrl-C is
    Python's KeyboardInterrupt (rclpy's signal handlers are not installed), and destroying it
    shuts rclpy down so the process ends cleanly."""

    def __init__(self, name: str) -> None:
        from rclpy.signals import SignalHandlerOptions
        from . import ensure_init
        ensure_init(None, signal_handler_options=SignalHandlerOptions.NO)
        from rclpy.parameter import Parameter
        super().__init__(name, start_parameter_services=False, enable_rosout=False,
                         parameter_overrides=[Parameter("start_type_description_service",
                                                        value=False)])
        self.context = SimpleNamespace(graph=PolledGraph(self))

    def destroy_node(self) -> None:
        import rclpy
        try:
            super().destroy_node()
        finally:
            rclpy.try_shutdown()


def make_node(name: str, settle: bool = True) -> CliNode:
    """The verb's node, named `name`, after discovery of the existing graph has settled."""
    node = CliNode(name)
    if settle:
        node.context.graph.wait_ready()
    return node
