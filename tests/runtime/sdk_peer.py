"""An independent rmw_zenoh implementation (PyPI zenoh-ros2-sdk) as a test peer, fully offline.

Modes: pub TOPIC | sub TOPIC | server NAME | client NAME. Prints one line per event.
Router address comes from ZENOH_CONFIG_OVERRIDE (the SDK applies it after its own default).
"""
from __future__ import annotations

import sys
import time

STRING_DEF = "string data\n"
ADD_REQ = "int64 a\nint64 b\n"
ADD_RESP = "int64 sum\n"


def out(*a) -> None:
    print(*a, flush=True)


def main() -> int:
    import zenoh_ros2_sdk as sdk
    mode, name = sys.argv[1], sys.argv[2]
    if mode == "pub":
        pub = sdk.ROS2Publisher(name, "std_msgs/msg/String", msg_definition=STRING_DEF, node_name="sdk_talker")
        out("HASH", pub.type_hash)
        out("READY")
        i = 0
        while True:
            pub.publish(data=f"sdk-{i}")
            i += 1
            time.sleep(0.05)
    elif mode == "sub":
        sdk.ROS2Subscriber(name, "std_msgs/msg/String", lambda m: out("GOT", m.data),
                           msg_definition=STRING_DEF, node_name="sdk_listener")
        out("READY")
        while True:
            time.sleep(1)
    elif mode == "server":
        holder = {}

        def cb(req):
            resp = holder["srv"].response_msg_class(sum=int(req.a) + int(req.b))
            out("REQUEST", req.a, req.b)
            return resp
        holder["srv"] = sdk.ROS2ServiceServer(name, "example_interfaces/srv/AddTwoInts", cb,
                                              request_definition=ADD_REQ, response_definition=ADD_RESP,
                                              node_name="sdk_server")
        out("READY")
        while True:
            time.sleep(1)
    elif mode == "client":
        cli = sdk.ROS2ServiceClient(name, "example_interfaces/srv/AddTwoInts", request_definition=ADD_REQ,
                                    response_definition=ADD_RESP, node_name="sdk_client", timeout=10.0)
        for _ in range(50):
            resp = cli.call(a=20, b=22)
            if resp is not None:
                out("SUM", resp.sum)
                return 0
            time.sleep(0.2)
        out("NO_RESPONSE")
        return 1
    return 2


if __name__ == "__main__":
    sys.exit(main())
