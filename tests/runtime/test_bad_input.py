"""Bad input is logged clearly and dropped; the node keeps serving."""
from __future__ import annotations

import os

import pytest
import zenoh

import roszen
from roszen import wire
from roszen.node import ServiceError
from roszen.testing import python_cmd, read_until, spawn, stop

PEER = os.path.join(os.path.dirname(__file__), "peer.py")
pytestmark = pytest.mark.graph
T = "example_interfaces/srv/AddTwoInts"


def test_malformed_cdr_and_missing_attachment(router_env):
    lis = spawn(python_cmd(PEER, "listener", "/bad_topic"), router_env)
    ctx = roszen.Context()
    try:
        read_until(lis, "READY")
        node = roszen.Node("bad_talker", context=ctx)
        pub = node.create_publisher("std_msgs/msg/String", "/bad_topic", 10)
        assert ctx.graph.wait_for(lambda: pub.get_subscription_count() > 0, 10)
        S = roszen.message_class("std_msgs/msg/String")
        # 1) a payload that is not a CDR String (length field far beyond the data)
        pub.publish(b"\x00\x01\x00\x00\xff\xff\xff\x7fxx")
        # 2) a valid payload without the rmw_zenoh attachment (rmw_zenoh drops these)
        good = S()
        good.data = "no-attachment"
        ctx.session.put(pub.key_expr, pub._sup.serialize(good))
        # 3) then a good sample: the listener is still serving
        good.data = "still-alive"
        import time
        for _ in range(100):
            pub.publish(good)
            try:
                lines = read_until(lis, "GOT still-alive", timeout=0.2)
                break
            except TimeoutError:
                continue
        else:
            pytest.fail("listener stopped receiving after bad input")
        assert "GOT no-attachment" not in lines
        err = read_until(lis, "malformed CDR payload", stream="stderr", timeout=5)
        if not any("without the rmw_zenoh attachment" in ln for ln in err):
            err += read_until(lis, "without the rmw_zenoh attachment", stream="stderr", timeout=5)
        text = "\n".join(err)
        assert "[ERROR]" in text and "/bad_topic" in text and "[WARN]" in text
        assert lis.poll() is None
    finally:
        stop(lis)
        ctx.shutdown()


def test_bad_requests_and_raising_handler(router_env):
    srv = spawn(python_cmd(PEER, "server", "/bad_srv"), router_env)
    ctx = roszen.Context()
    try:
        read_until(srv, "READY")
        node = roszen.Node("bad_client", context=ctx)
        cli = node.create_client(T, "/bad_srv")
        assert cli.wait_for_service(10)
        Req = roszen.request_class(T)
        # a request body that is not an AddTwoInts request, sent with a valid attachment
        replies = list(ctx.session.get(cli.key_expr, payload=b"\x00\x01\x00\x00\x01",
                                       attachment=wire.make_attachment(1, cli.gid),
                                       target=zenoh.QueryTarget.ALL_COMPLETE, timeout=10))
        assert len(replies) == 1 and replies[0].err is not None
        assert "malformed request" in replies[0].err.payload.to_bytes().decode()
        # the handler raises for a == 13: the client gets a ServiceError naming the exception
        req = Req()
        req.a, req.b = 13, 1
        with pytest.raises(ServiceError, match="unlucky number"):
            cli.call(req, timeout_sec=10)
        # a client of another type on the same name never reaches this server (type in the key)
        other = node.create_client("std_srvs/srv/Trigger", "/bad_srv")
        assert not other.wait_for_service(0.2)
        with pytest.raises(ServiceError, match="no service server replied"):
            other.call(roszen.request_class("std_srvs/srv/Trigger")(), timeout_sec=10)
        # and the server still serves good requests
        req.a, req.b = 40, 2
        assert cli.call(req, timeout_sec=10).sum == 42
        err = "\n".join(read_until(srv, "unlucky number", stream="stderr", timeout=5))
        assert "malformed request" in err and "Traceback" in err
        assert srv.poll() is None
    finally:
        stop(srv)
        ctx.shutdown()


def test_wrong_message_type_to_publish_is_rejected(router_env):
    node = roszen.Node("typed_pub")
    try:
        pub = node.create_publisher("std_msgs/msg/String", "/typed", 10)
        with pytest.raises(TypeError, match="expects std_msgs/msg/String"):
            pub.publish(roszen.message_class("std_msgs/msg/Int32")())
    finally:
        node.destroy_node()
