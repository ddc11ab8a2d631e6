"""The runtime the nodes run on, chosen per process: roszen over rmw_zenoh's wire (the default,
no ROS install needed) or real rclpy (ASTROBEE_RUNTIME=rclpy: a sourced ROS 2 Jazzy with any
RMW, or the PyPI wheels of `make install-rclpy`). Node modules import this module in place of
`roszen` (`from roszen import runtime as roszen`) and so run unchanged on either.

The same on both: message classes by type name, the CDR codec, QoS profiles and parameter
descriptors (roszen's; the rclpy backend converts at its edge). Chosen by the variable:
`Node`, `Clock` (`Clock(False)`: a wall clock), `ok`, `shutdown`, `node_main`."""
from __future__ import annotations

import os
from types import ModuleType
from typing import Any

from . import codec  # noqa: F401 - re-exported: the same on both runtimes
from .qos import (CLOCK, LATCHED, SENSOR_DATA, Durability, History,  # noqa: F401
                  QoSProfile, Reliability)

ENV = "ASTROBEE_RUNTIME"
RUNTIMES = ("roszen", "rclpy")
SELECTED = ("Node", "Clock", "ok", "shutdown", "node_main")


def name() -> str:
    """The runtime chosen by ASTROBEE_RUNTIME ('roszen' when unset); ValueError for another."""
    value = os.environ.get(ENV, "").strip().lower() or "roszen"
    if value not in RUNTIMES:
        raise ValueError(f"{ENV}={value!r}: expected one of {', '.join(RUNTIMES)}")
    return value


def backend() -> ModuleType:
    """The module that provides the selected names: roszen itself or roszen.rclpy_backend."""
    if name() == "rclpy":
        from . import rclpy_backend
        return rclpy_backend
    import roszen
    return roszen


def message_class(type_name: str) -> type:
    """The (roszen) class of 'pkg/msg/Name', on both runtimes."""
    from . import typestore
    return typestore.message_class(type_name)


def request_class(type_name: str) -> type:
    from . import typestore
    return typestore.request_class(type_name)


def response_class(type_name: str) -> type:
    from . import typestore
    return typestore.response_class(type_name)


def __getattr__(attr: str) -> Any:
    """Node, Clock, ok, shutdown, node_main of the selected runtime."""
    if attr not in SELECTED:
        raise AttributeError(f"module {__name__!r} has no attribute {attr!r}")
    mod = backend()
    if attr == "Clock" and mod.__name__ != "roszen":
        return mod.wall_clock
    if attr == "node_main" and mod.__name__ == "roszen":
        from . import node_main
        return node_main
    return getattr(mod, attr)
