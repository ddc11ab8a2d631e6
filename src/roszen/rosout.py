"""Mirror a node's log records to /rosout (rcl_interfaces/msg/Log), as rclpy does."""
from __future__ import annotations

import time
from typing import Optional

from . import codec
from .qos import ROSOUT


def attach_rosout(node) -> Optional[object]:
    """Create the /rosout publisher and hook it to the node's logger (None if the type is unknown).

    The record's file/function/line come from the call site the logger already resolved: no
    frame object is taken here (a frame kept in a local forms a cycle with it and would pin the
    caller's locals, e.g. a bad sample's payload, until a full garbage collection).
    """
    try:
        pub = node.create_publisher("rcl_interfaces/msg/Log", "/rosout", ROSOUT)
    except (codec.TypeSupportError, ImportError, KeyError):
        return None
    cls = pub._sup.cls

    def sink(level, name, msg, site=None) -> None:
        if not node._alive:
            return
        m = cls()
        ns = time.time_ns()
        m.stamp.sec, m.stamp.nanosec = divmod(ns, 1_000_000_000)
        m.level = int(level)
        m.name = name
        m.msg = msg
        if site is not None:
            m.file, m.line, m.function = site[0], site[1], site[2]
        pub.publish(m)

    node.get_logger().sink = sink
    return pub
