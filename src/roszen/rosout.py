"""Mirror a node's log records to /rosout (rcl_interfaces/msg/Log), as rclpy does."""
from __future__ import annotations

import inspect
import time
from typing import Optional

from . import codec
from .qos import ROSOUT


def attach_rosout(node) -> Optional[object]:
    """Create the /rosout publisher and hook it to the node's logger (None if the type is unknown)."""
    try:
        pub = node.create_publisher("rcl_interfaces/msg/Log", "/rosout", ROSOUT)
    except (codec.TypeSupportError, ImportError, KeyError):
        return None
    cls = pub._sup.cls

    def sink(level, name, msg) -> None:
        if not node._alive:
            return
        m = cls()
        ns = time.time_ns()
        m.stamp.sec, m.stamp.nanosec = divmod(ns, 1_000_000_000)
        m.level = int(level)
        m.name = name
        m.msg = msg
        fr = inspect.currentframe()
        caller = fr.f_back.f_back.f_back if fr and fr.f_back and fr.f_back.f_back else None
        if caller is not None and caller.f_back is not None:
            caller = caller.f_back
            m.file, m.function, m.line = caller.f_code.co_filename, caller.f_code.co_name, caller.f_lineno
        pub.publish(m)

    node.get_logger().sink = sink
    return pub
