"""Child processes for test_hardening.py (one mode per invocation, events on stdout)."""
from __future__ import annotations

import sys
import time

import roszen
from roszen.node import Subscription


def out(*a) -> None:
    print(*a, flush=True)


def no_destroy() -> None:
    """Create a node with a subscription, publisher and service, then just end main()."""
    node = roszen.Node("no_destroy")
    node.create_subscription("std_msgs/msg/String", "/nd", lambda m: None, 10)
    node.create_publisher("std_msgs/msg/String", "/nd", 10)
    node.create_service("std_srvs/srv/Trigger", "/nd_srv", lambda req: None)
    out("READY")


def sigint_in_direct_callback() -> None:
    """Publish in a loop to a same-session subscription whose (direct) callback sleeps: a
    SIGINT then almost always lands inside a zenoh callback running on the main thread."""
    node = roszen.Node("sigint_direct")
    S = roszen.message_class("std_msgs/msg/String")
    pub = node.create_publisher("std_msgs/msg/String", "/sigint_direct", 10)
    got = []
    Subscription(node, "std_msgs/msg/String", "/sigint_direct",
                 lambda m: (got.append(1), time.sleep(0.05)), pub.qos_profile, direct=True)
    m = S()
    m.data = "x"
    try:
        while True:
            pub.publish(m)
            if len(got) == 3:
                out("READY")
            node.spin_once(0)
    except KeyboardInterrupt:
        out("INTERRUPTED")
    finally:
        node.destroy_node()


if __name__ == "__main__":
    {"no_destroy": no_destroy, "sigint_direct": sigint_in_direct_callback}[sys.argv[1]]()
