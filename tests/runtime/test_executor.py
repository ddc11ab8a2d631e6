"""The executor: no loss under load for KEEP_ALL / deep KEEP_LAST, bounded KEEP_LAST history, timers."""
from __future__ import annotations

import threading
import time

import pytest

import roszen
from roszen import History, QoSProfile


@pytest.fixture
def node(router_env):
    n = roszen.Node("exec_test")
    yield n
    n.destroy_node()


def _publish_burst(node, topic, count):
    S = roszen.message_class("std_msgs/msg/Int32")
    pub = node.create_publisher("std_msgs/msg/Int32", topic, QoSProfile(depth=count, history=History.KEEP_ALL))
    time.sleep(0.2)
    for i in range(count):
        m = S()
        m.data = i
        pub.publish(m)
    return pub


def _drain(node, got, want, timeout=10.0):
    end = time.monotonic() + timeout
    while len(got) < want and time.monotonic() < end:
        node.spin_once(0.05)
    # anything else already queued
    while node.spin_once(0):
        pass


def test_keep_all_burst_no_loss_in_order(node):
    got = []
    node.create_subscription("std_msgs/msg/Int32", "/burst", lambda m: got.append(m.data),
                             QoSProfile(depth=1, history=History.KEEP_ALL))
    _publish_burst(node, "/burst", 2000)
    _drain(node, got, 2000)
    assert got == list(range(2000))


def test_keep_last_depth_bounds_the_queue(node):
    got = []
    node.create_subscription("std_msgs/msg/Int32", "/lastn", lambda m: got.append(m.data), 5)
    _publish_burst(node, "/lastn", 200)
    time.sleep(0.5)  # everything has arrived; nothing was taken yet
    _drain(node, got, 5, timeout=2)
    assert got == list(range(195, 200))


def test_timer_and_callbacks_share_one_thread(node):
    threads, ticks = set(), []
    t = node.create_timer(0.01, lambda: (ticks.append(1), threads.add(threading.get_ident())))
    node.create_subscription("std_msgs/msg/Int32", "/tt", lambda m: threads.add(threading.get_ident()), 10)
    _publish_burst(node, "/tt", 10)
    end = time.monotonic() + 5
    while len(ticks) < 5 and time.monotonic() < end:
        node.spin_once(0.1)
    assert len(ticks) >= 5 and threads == {threading.get_ident()}
    t.cancel()
    n = len(ticks)
    for _ in range(5):
        node.spin_once(0.02)
    assert len(ticks) == n


TRIGGER = "std_srvs/srv/Trigger"


def _trigger(node, name: str, message: str):
    """A Trigger service ~/<name> on `node` answering `message`, and a client of it, ready."""
    def handle(req):
        r = roszen.response_class(TRIGGER)()
        r.success, r.message = True, message
        return r
    node.create_service(TRIGGER, f"~/{name}", handle)
    cli = node.create_client(TRIGGER, f"/exec_test/{name}")
    assert cli.wait_for_service(5)
    return cli


def test_spin_until_future_complete_with_async_call(node):
    cli = _trigger(node, "trigger", "done")
    fut = cli.call_async(roszen.request_class(TRIGGER)())
    roszen.spin_until_future_complete(node, fut, timeout_sec=10)
    assert fut.done() and fut.result().message == "done"


def test_service_replies_are_read_off_zenohs_thread_while_entities_come_and_go(node):
    """A call's replies come through zenoh's channel to a reader thread of the client's, not a
    Python callback zenoh would drop on its own thread under the session's lock (the deadlock
    roszen.graph's start-up query once hit against a node undeclaring a publisher); calls made
    while publishers are declared and undeclared all complete."""
    cli = _trigger(node, "churn", "ok")
    threads = []
    for k in range(30):
        fut = cli.call_async(roszen.request_class(TRIGGER)())
        fut.add_done_callback(lambda f: threads.append(threading.current_thread().name))
        pub = node.create_publisher("std_msgs/msg/Int32", f"/churn{k}", QoSProfile(depth=1))
        node.destroy_publisher(pub)
        roszen.spin_until_future_complete(node, fut, timeout_sec=10)
        assert fut.done() and fut.result().message == "ok"
    assert len(threads) == 30 and all(t.startswith("roszen-client") for t in threads), threads[:3]


def test_a_timed_out_call_ends_its_query_and_reader_thread(node):
    """call() timing out cancels the zenoh query, so the call's reader thread ends at once
    instead of waiting out the querier's timeout (a caller retrying a stuck service would pile
    them up): the server here is never spun, so it never answers."""
    cli = _trigger(node, "stuck", "never")
    with pytest.raises(TimeoutError):
        cli.call(roszen.request_class(TRIGGER)(), timeout_sec=0.2)

    def readers():
        return [t for t in threading.enumerate() if t.name == "roszen-client/exec_test/stuck"]
    end = time.monotonic() + 5.0
    while readers() and time.monotonic() < end:
        time.sleep(0.05)
    assert not readers()
