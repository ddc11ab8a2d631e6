"""A small node process used by the multi-process runtime tests (one mode per invocation).

Prints one line per event on stdout so the test can follow it with read_until().
"""
from __future__ import annotations

import sys
import time

import roszen
from roszen import LATCHED, Node


def out(*a) -> None:
    print(*a, flush=True)


def talker(node: Node, topic: str, n: int, latched: bool) -> None:
    S = roszen.message_class("std_msgs/msg/String")
    pub = node.create_publisher("std_msgs/msg/String", topic, LATCHED if latched else 10)
    if latched:
        m = S()
        m.data = "latched-0"
        pub.publish(m)
        out("PUBLISHED latched-0")
        node.spin()
        return
    out("READY")
    # wait for a subscriber in the graph, then publish n messages at a gentle pace, forever repeating
    while pub.get_subscription_count() == 0:
        node.spin_once(0.05)
    out("PUBLISHING")
    i = 0
    while True:
        m = S()
        m.data = f"msg-{i}"
        pub.publish(m)
        i += 1
        node.spin_once(0.02)
        if n and i >= n:
            node.spin()
            return


def listener(node: Node, topic: str, latched: bool) -> None:
    node.create_subscription("std_msgs/msg/String", topic, lambda m: out("GOT", m.data),
                             LATCHED if latched else 10)
    out("READY")
    node.spin()


def server(node: Node, name: str) -> None:
    T = "example_interfaces/srv/AddTwoInts"
    Resp = roszen.response_class(T)

    def add(req):
        if req.a == 13:
            raise RuntimeError("unlucky number")
        r = Resp()
        r.sum = req.a + req.b
        return r
    node.create_service(T, name, add)
    out("READY")
    node.spin()


def client(node: Node, name: str) -> None:
    T = "example_interfaces/srv/AddTwoInts"
    cli = node.create_client(T, name)
    if not cli.wait_for_service(10.0):
        out("NO_SERVICE")
        return
    req = roszen.request_class(T)()
    req.a, req.b = 40, 2
    out("SUM", cli.call(req, timeout_sec=10.0).sum)


def params(node: Node) -> None:
    node.declare_parameter("rate", 1.0)
    node.declare_parameter("name", "none")
    node.declare_parameter("gains", [0.0])
    node.declare_parameter("enabled", False)
    for k in ("rate", "name", "gains", "enabled"):
        out("PARAM", k, repr(node.get_parameter(k).value))
    out("NAME", node.get_fully_qualified_name(), node.resolve_topic_name("chatter"),
        node.resolve_topic_name("~/private"))
    out("DONE")


def simtime(node: Node) -> None:
    ticks = []
    node.create_timer(0.5, lambda: (ticks.append(node.get_clock().now().nanoseconds),
                                    out("TICK", node.get_clock().now().nanoseconds)))
    out("READY", node.get_clock().ros_time_is_active)
    node.spin()


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    mode = argv.pop(0)
    node = Node(f"peer_{mode}", argv=argv)
    rest = node.user_args
    try:
        if mode == "talker":
            talker(node, rest[0], int(rest[1]) if len(rest) > 1 and rest[1].isdigit() else 0, "latched" in rest)
        elif mode == "listener":
            listener(node, rest[0], "latched" in rest)
        elif mode == "server":
            server(node, rest[0])
        elif mode == "client":
            client(node, rest[0])
        elif mode == "params":
            params(node)
        elif mode == "simtime":
            simtime(node)
        else:
            out("BAD_MODE", mode)
            return 2
    except KeyboardInterrupt:
        pass
    finally:
        roszen.shutdown()
    return 0


if __name__ == "__main__":
    time.sleep(0)
    sys.exit(main())
