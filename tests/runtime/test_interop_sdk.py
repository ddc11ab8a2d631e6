"""Interop with an independent implementation (zenoh-ros2-sdk from PyPI), both directions."""
from __future__ import annotations

import os
import time
import threading

import pytest

import roszen
from roszen import typestore
from roszen.testing import python_cmd, read_until, spawn, stop

SDK = os.path.join(os.path.dirname(__file__), "sdk_peer.py")
pytestmark = pytest.mark.graph
pytest.importorskip("zenoh_ros2_sdk")


class Spinner:
    """Spin a node on a background thread for the duration of a with-block."""

    def __init__(self, node):
        self.node, self.ev = node, threading.Event()
        self.th = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        while not self.ev.is_set():
            self.node.spin_once(0.05)

    def __enter__(self):
        self.th.start()
        return self

    def __exit__(self, *exc):
        self.ev.set()
        self.th.join(5)


def test_sdk_publisher_to_our_subscription(router_env):
    p = spawn(python_cmd(SDK, "pub", "/sdk_chatter"), router_env)
    ctx = roszen.Context()
    try:
        lines = read_until(p, "READY", timeout=20)
        assert f"HASH {typestore.type_hash('std_msgs/msg/String')}" in lines
        node = roszen.Node("our_listener", context=ctx)
        got = []
        done = threading.Event()

        def cb(m):
            got.append(m.data)
            if len(got) >= 3:
                done.set()
        node.create_subscription("std_msgs/msg/String", "/sdk_chatter", cb, 10)
        with Spinner(node):
            assert done.wait(15), got
        assert all(g.startswith("sdk-") for g in got)
        # its node and topic are in our graph cache
        assert ("sdk_talker", "/") in ctx.graph.get_node_names_and_namespaces()
        assert ctx.graph.count_publishers("/sdk_chatter") == 1
    finally:
        stop(p)
        ctx.shutdown()


def test_our_publisher_to_sdk_subscription(router_env):
    p = spawn(python_cmd(SDK, "sub", "/our_chatter"), router_env)
    ctx = roszen.Context()
    try:
        read_until(p, "READY", timeout=20)
        node = roszen.Node("our_talker", context=ctx)
        S = roszen.message_class("std_msgs/msg/String")
        pub = node.create_publisher("std_msgs/msg/String", "/our_chatter", 10)
        assert ctx.graph.wait_for(lambda: pub.get_subscription_count() > 0, 15)
        stop_ev = threading.Event()

        def pump():
            i = 0
            while not stop_ev.is_set():
                m = S()
                m.data = f"ours-{i}"
                pub.publish(m)
                i += 1
                stop_ev.wait(0.05)
        th = threading.Thread(target=pump, daemon=True)
        th.start()
        try:
            lines = read_until(p, "GOT ours-", timeout=15)
        finally:
            stop_ev.set()
            th.join(5)
        assert lines[-1].startswith("GOT ours-")
    finally:
        stop(p)
        ctx.shutdown()


def test_our_client_calls_sdk_server(router_env):
    p = spawn(python_cmd(SDK, "server", "/sdk_add"), router_env)
    ctx = roszen.Context()
    try:
        read_until(p, "READY", timeout=20)
        node = roszen.Node("our_client", context=ctx)
        T = "example_interfaces/srv/AddTwoInts"
        cli = node.create_client(T, "/sdk_add")
        assert cli.wait_for_service(15)
        req = roszen.request_class(T)()
        req.a, req.b = 5, 7
        # zenoh-ros2-sdk may declare its liveliness token before its queryable reaches the
        # router, so the graph can show the server a moment before it answers: retry a
        # "no server replied" for a bounded time (a wrong or missing answer still fails).
        deadline = time.monotonic() + 10
        while True:
            try:
                resp = cli.call(req, timeout_sec=10)
                break
            except roszen.ServiceError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
        assert resp.sum == 12
    finally:
        stop(p)
        ctx.shutdown()


def test_sdk_client_calls_our_server(router_env):
    ctx = roszen.Context()
    node = roszen.Node("our_server", context=ctx)
    T = "example_interfaces/srv/AddTwoInts"
    Resp = roszen.response_class(T)

    def add(req):
        r = Resp()
        r.sum = req.a + req.b
        return r
    node.create_service(T, "/our_add", add)
    p = spawn(python_cmd(SDK, "client", "/our_add"), router_env)
    try:
        with Spinner(node):
            lines = read_until(p, "SUM", timeout=30)
        assert lines[-1] == "SUM 42"
    finally:
        stop(p)
        ctx.shutdown()
