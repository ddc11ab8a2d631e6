"""hardening of the runtime: bounded memory and logs under floods, processes that
exit, Ctrl-C never swallowed, spoofed attachments dropped (each test reproduced the fault first)."""
from __future__ import annotations

import gc
import os
import signal
import subprocess
import weakref

import pytest
import zenoh

import roszen
from roszen import log as rlog
from roszen import wire
from roszen.node import DEFAULT_MAX_BYTES, ServiceError, _max_bytes_default
from roszen.testing import python_cmd, read_until, spawn, stop

PEER = os.path.join(os.path.dirname(__file__), "hardening_peer.py")
S = "std_msgs/msg/String"


def _spin_until(node, cond, limit: float = 10.0) -> bool:
    import time
    end = time.monotonic() + limit
    while not cond() and time.monotonic() < end:
        node.spin_once(0.05)
    return cond()


# -- logs -----------------------------------------------------------------------------------------
class _Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def test_log_flood_from_one_place_is_rate_limited_with_a_count(capsys):
    logger = rlog.Logger("flood")
    clock = _Clock()
    logger._limiter.clock = clock

    def report(i: int) -> None:   # one call site; the numbers differ: one message shape
        logger.error(f"dropped a sample from {i:032x}: malformed ({i} bytes)")
    for i in range(1000):
        report(i)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == rlog.RATE_LIMIT
    clock.t += 1.5
    report(7)
    last = capsys.readouterr().err.splitlines()
    assert len(last) == 1 and f"(suppressed {1000 - rlog.RATE_LIMIT} similar messages)" in last[0]


def test_log_distinct_messages_from_one_place_are_capped(capsys):
    logger = rlog.Logger("flood2")
    logger._limiter.clock = _Clock()
    for i in range(500):
        logger.warn(f"peer says {chr(65 + i % 26) * (1 + i // 26)}")   # no digits: all shapes differ
    assert len(capsys.readouterr().err.splitlines()) == rlog.SITE_LIMIT


def test_other_call_sites_are_not_suppressed(capsys):
    logger = rlog.Logger("sites")
    logger._limiter.clock = _Clock()
    for _ in range(100):
        logger.info("same")
    logger.info("elsewhere")
    err = capsys.readouterr().err
    assert "elsewhere" in err


def test_long_log_strings_are_truncated(capsys):
    logger = rlog.Logger("long")
    logger.error("x" * 10_000_000)
    err = capsys.readouterr().err
    assert len(err) < rlog.MAX_CHARS + 200
    assert "[truncated, 10000000 characters]" in err


@pytest.mark.graph
def test_rosout_keeps_no_frame_alive(router_env):
    """A logged error must not pin the logging frame's locals (e.g. a bad sample's payload)."""
    class Payload:
        pass

    node = roszen.Node("rosout_frames")
    assert node._rosout is not None

    def handle_bad_sample():
        payload = Payload()
        node.get_logger().error("bad sample")
        return weakref.ref(payload)

    gc.disable()
    try:
        ref = handle_bad_sample()
        assert ref() is None, "the rosout sink kept the caller's frame (and its payload) alive"
    finally:
        gc.enable()
        node.destroy_node()


# -- incoming size limits -------------------------------------------------------------------------
def test_default_size_limit_is_generous_and_configurable(monkeypatch):
    monkeypatch.delenv("ROSZEN_MAX_MESSAGE_BYTES", raising=False)
    assert _max_bytes_default() == DEFAULT_MAX_BYTES == 16 * 1024 * 1024
    monkeypatch.setenv("ROSZEN_MAX_MESSAGE_BYTES", "1234")
    assert _max_bytes_default() == 1234
    monkeypatch.setenv("ROSZEN_MAX_MESSAGE_BYTES", "junk")
    assert _max_bytes_default() == DEFAULT_MAX_BYTES


@pytest.mark.graph
def test_oversize_sample_is_dropped_and_logged_once(router_env, capsys):
    node = roszen.Node("size_limit")
    try:
        got = []
        sub = node.create_subscription(S, "/size_limit", lambda m: got.append(m.data), 10, max_bytes=1000)
        pub = node.create_publisher(S, "/size_limit", 10)
        M = roszen.message_class(S)
        for text in ("a" * 5000, "b" * 5000, "small"):
            m = M()
            m.data = text
            pub.publish(m)
        assert _spin_until(node, lambda: "small" in got)
        assert got == ["small"] and sub.dropped == 2
        err = capsys.readouterr().err
        assert err.count("larger than this subscription's limit of 1000 bytes") == 1
    finally:
        node.destroy_node()


@pytest.mark.graph
def test_oversize_request_gets_an_error_reply(router_env):
    import threading
    node = roszen.Node("srv_limit")
    T = "example_interfaces/srv/AddTwoInts"
    Resp = roszen.response_class(T)

    def add(req):
        r = Resp()
        r.sum = req.a + req.b
        return r
    stop_ev = threading.Event()
    try:
        node.create_service(T, "/srv_limit", add, max_bytes=64)
        cli = node.create_client(T, "/srv_limit")
        th = threading.Thread(target=lambda: [node.spin_once(0.05) for _ in iter(stop_ev.is_set, True)],
                              daemon=True)
        th.start()
        assert cli.wait_for_service(10)
        replies = list(node.context.session.get(cli.key_expr, payload=b"\x00\x01\x00\x00" + b"\x00" * 10_000,
                                                attachment=wire.make_attachment(1, cli.gid),
                                                target=zenoh.QueryTarget.ALL_COMPLETE, timeout=10))
        assert len(replies) == 1 and replies[0].err is not None
        assert "larger than this service's limit of 64 bytes" in replies[0].err.payload.to_bytes().decode()
        req = roszen.request_class(T)()
        req.a, req.b = 40, 2
        assert cli.call(req, timeout_sec=10).sum == 42
    finally:
        stop_ev.set()
        th.join(5)
        node.destroy_node()


# -- spoofed attachments --------------------------------------------------------------------------
@pytest.mark.graph
def test_samples_with_a_malformed_attachment_are_dropped(router_env, capsys):
    node = roszen.Node("att_check")
    try:
        got = []
        sub = node.create_subscription(S, "/att_check", lambda m: got.append(m.data), 100)
        pub = node.create_publisher(S, "/att_check", 10)
        M = roszen.message_class(S)
        m = M()
        m.data = "spoofed"
        data = pub._sup.serialize(m)
        bad = [b"", b"\x01", b"\x00" * 5, b"\x00" * 64, b"\x00" * 16 + b"\x0f" + b"\x00" * 16]
        for att in bad:
            node.context.session.put(pub.key_expr, data, attachment=att)
        m.data = "real"
        pub.publish(m)
        assert _spin_until(node, lambda: "real" in got)
        assert got == ["real"] and sub.dropped == len(bad)
        assert capsys.readouterr().err.count("malformed rmw_zenoh attachment") == 1
    finally:
        node.destroy_node()


# -- processes that end, Ctrl-C -------------------------------------------------------------------
@pytest.mark.graph
def test_program_ending_without_destroy_node_exits(router_env):
    p = spawn(python_cmd(PEER, "no_destroy"), router_env)
    try:
        read_until(p, "READY", timeout=30)
        assert p.wait(60) == 0   # hung forever on zenoh's non-daemon callback threads before
    finally:
        stop(p)


@pytest.mark.graph
def test_sigint_in_a_callback_run_by_zenoh_on_the_main_thread_is_not_swallowed(router_env):
    p = spawn(python_cmd(PEER, "sigint_direct"), router_env)
    try:
        read_until(p, "READY", timeout=30)
        os.kill(p.pid, signal.SIGINT)
        read_until(p, "INTERRUPTED", timeout=30)
        assert p.wait(30) == 0
    finally:
        stop(p)


def test_keyboard_interrupt_in_a_callback_propagates_out_of_spin(router_env):
    node = roszen.Node("ki_spin")
    try:
        calls = []

        def tick():
            calls.append(1)
            if len(calls) == 1:
                raise KeyboardInterrupt
        node.create_timer(0.01, tick)
        with pytest.raises(KeyboardInterrupt):
            node.spin()
        got = []

        def on_msg(m):
            got.append(m.data)
            if m.data == "stop":
                raise SystemExit(3)
        node.create_subscription(S, "/ki_spin", on_msg, 10)
        pub = node.create_publisher(S, "/ki_spin", 10)
        M = roszen.message_class(S)
        for text in ("stop", "after"):
            m = M()
            m.data = text
            pub.publish(m)
        with pytest.raises(SystemExit):
            _spin_until(node, lambda: False, 30)
        assert _spin_until(node, lambda: "after" in got)   # the subscription still serves
    finally:
        node.destroy_node()
