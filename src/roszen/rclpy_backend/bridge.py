"""The edge between roszen's message objects and real rclpy: rosidl's generated classes found by
type name (for rclpy's type support), roszen QoS profiles as rclpy's, CDR bytes both ways.

The nodes keep roszen's message classes on both runtimes (numpy arrays, the same defaults, the
same encoder): on rclpy a message crosses as its CDR bytes (raw publish / raw subscription;
services through rclpy.serialization), the same bytes as the typestore's (RIHS01 hashes equal)."""
from __future__ import annotations

import importlib
import traceback
from typing import Any, Callable

from .. import codec
from ..qos import QoSProfile, as_qos
from ..types.cdr import MessageDecodeError


def rosidl_class(type_name: str, kind: str = "msg") -> type:
    """rosidl's generated class of 'pkg/msg/Name' (a service's class for 'pkg/srv/Name'); an
    unbuilt package is one line naming `make install-rclpy`."""
    name = codec.normalize_type_name(type_name, kind)
    pkg, sub, cls = name.split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.{sub}"), cls)
    except (ImportError, AttributeError) as exc:
        raise codec.TypeSupportError(
            f"{name}: no rosidl class in this environment ({exc}); build the interfaces with "
            f"`make install-rclpy` or source a ROS 2 Jazzy install") from None


def type_name_of(t: Any, kind: str = "msg") -> str:
    """The 'pkg/kind/Name' of a type name, a roszen class or a rosidl class."""
    if isinstance(t, str):
        return codec.normalize_type_name(t, kind)
    for attr in ("__msgtype__", "_type", "__typename__", "TYPE_NAME"):
        v = getattr(t, attr, None)
        if isinstance(v, str):
            return codec.normalize_type_name(v, kind)
    mod = getattr(t, "__module__", "")            # rosidl: pkg.msg._name.Name
    parts = mod.split(".")
    if len(parts) >= 2 and parts[1] in ("msg", "srv"):
        return f"{parts[0]}/{parts[1]}/{t.__name__}"
    raise TypeError(f"pass the type as a name like 'pkg/{kind}/Name', got {t!r}")


def rclpy_qos(qos: "QoSProfile | int | None") -> Any:
    """rclpy's QoSProfile for a roszen profile or depth (the enum values are rmw's in both)."""
    from rclpy.duration import Duration
    from rclpy.qos import (DurabilityPolicy, HistoryPolicy, LivelinessPolicy,
                           QoSProfile as RclpyQoS, ReliabilityPolicy)
    q = as_qos(qos)
    kw: dict = {}
    if q.deadline > 0:
        kw["deadline"] = Duration(nanoseconds=int(q.deadline * 1e9))
    if q.lifespan > 0:
        kw["lifespan"] = Duration(nanoseconds=int(q.lifespan * 1e9))
    return RclpyQoS(depth=q.effective_depth, history=HistoryPolicy(int(q.history)),
                    reliability=ReliabilityPolicy(int(q.reliability)),
                    durability=DurabilityPolicy(int(q.durability)),
                    liveliness=LivelinessPolicy(int(q.liveliness)), **kw)


def to_rosidl(msg: Any, support: codec.MsgSupport, cls: type) -> Any:
    """A roszen message as rosidl's object (through its CDR bytes)."""
    from rclpy.serialization import deserialize_message
    return deserialize_message(bytes(support.serialize(msg)), cls)


def from_rosidl(obj: Any, support: codec.MsgSupport) -> Any:
    """A rosidl object as roszen's message (through its CDR bytes)."""
    from rclpy.serialization import serialize_message
    return decode(support, serialize_message(obj))


def decode(support: codec.MsgSupport, data: bytes) -> Any:
    """roszen's message from CDR bytes rmw_fastrtps may have padded: Fast-CDR's size estimate
    can leave bytes after the message (8 per rcl_interfaces ParameterValue: a GetParameters
    response of one double is 64 bytes for 56), more than roszen's decoder accepts (3). Only when
    the whole payload is refused for trailing bytes, the message's own length is searched for
    (bisection: a shorter cut fails to decode, a longer one has trailing bytes)."""
    try:
        return support.deserialize(data)
    except MessageDecodeError as exc:
        if "trailing bytes" not in str(exc):
            raise
        first = exc
    lo, hi = 4, len(data) - 1
    while lo <= hi:
        mid = (lo + hi) // 2
        try:
            return support.deserialize(data[:mid])
        except MessageDecodeError as exc:
            if "trailing bytes" in str(exc):
                hi = mid - 1
            else:
                lo = mid + 1
    raise first


def guarded(callback: Callable, log: Any, what: str, count: list) -> Callable:
    """`callback` that never raises into rclpy's executor (an exception is logged with its
    traceback, as roszen does; KeyboardInterrupt/SystemExit pass) and counts its runs."""
    def run(*args: Any) -> Any:
        count[0] += 1
        try:
            return callback(*args)
        except Exception as exc:  # noqa: BLE001 - a callback error must not end the spin
            log.error(f"{what}: {type(exc).__name__}: {exc}\n{traceback.format_exc()}")
            return None
    return run
