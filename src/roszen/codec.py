"""Per-type support for the transport: DDS name, RIHS01 hash and CDR (de)serialisers.

Everything type-specific comes from `roszen.typestore`; this module only caches it.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any, Callable

from .wire import ros_to_dds_type


class TypeSupportError(LookupError):
    """The type is unknown to the typestore."""


@dataclass(frozen=True)
class MsgSupport:
    """A message type as the wire needs it."""
    name: str
    dds_name: str
    type_hash: str
    cls: type
    serialize: Callable[[Any], bytes]
    deserialize: Callable[[bytes], Any]


@dataclass(frozen=True)
class SrvSupport:
    """A service type: request and response halves share the service's name and hash."""
    name: str
    dds_name: str
    type_hash: str
    request: MsgSupport
    response: MsgSupport


_lock = threading.Lock()
_msgs: dict = {}
_srvs: dict = {}


def _ts():
    from . import typestore
    return typestore


def normalize_type_name(name: str, kind: str = "msg") -> str:
    """'std_msgs/String' -> 'std_msgs/msg/String'; full names pass through."""
    if hasattr(name, "__msgtype__") or isinstance(name, type):
        name = getattr(name, "__msgtype__", None) or getattr(name, "_type", None) or name.__name__
    parts = name.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/{kind}/{parts[1]}"
    if len(parts) != 3:
        raise TypeSupportError(f"bad type name {name!r} (expected pkg/{kind}/Name)")
    return name


def msg_support(name: str) -> MsgSupport:
    """Cached wire support for a message type like 'geometry_msgs/msg/PoseStamped'."""
    name = normalize_type_name(name, "msg")
    sup = _msgs.get(name)
    if sup is not None:
        return sup
    ts = _ts()
    try:
        cls = ts.message_class(name)
        thash = ts.type_hash(name)
    except (KeyError, LookupError, ValueError) as e:
        raise TypeSupportError(f"unknown message type {name!r}: {e}") from e
    ser = _serializer(ts, name)
    de = _deserializer(ts, name)
    sup = MsgSupport(name, ros_to_dds_type(name), thash, cls, ser, de)
    with _lock:
        _msgs[name] = sup
    return sup


def _serializer(ts, name: str) -> Callable[[Any], bytes]:
    """The typestore's encoder itself (no per-call name lookup); lazy if it cannot be built yet."""
    try:
        return ts.serializer(name)
    except Exception:  # noqa: BLE001 - reported with context on first use
        fn = ts.serialize
        return lambda msg: fn(msg, name)


def _deserializer(ts, name: str) -> Callable[[bytes], Any]:
    try:
        return ts.deserializer(name)
    except Exception:  # noqa: BLE001
        fn = ts.deserialize
        return lambda data: fn(data, name)


def srv_support(name: str) -> SrvSupport:
    """Cached wire support for a service type like 'std_srvs/srv/Trigger'."""
    name = normalize_type_name(name, "srv")
    sup = _srvs.get(name)
    if sup is not None:
        return sup
    ts = _ts()
    try:
        thash = ts.type_hash(name)
        req_cls, resp_cls = ts.request_class(name), ts.response_class(name)
    except (KeyError, LookupError, ValueError) as e:
        raise TypeSupportError(f"unknown service type {name!r}: {e}") from e
    dds = ros_to_dds_type(name)
    rq, rs = name + "_Request", name + "_Response"
    req = MsgSupport(rq, ros_to_dds_type(rq), thash, req_cls, _serializer(ts, rq), _deserializer(ts, rq))
    resp = MsgSupport(rs, ros_to_dds_type(rs), thash, resp_cls, _serializer(ts, rs), _deserializer(ts, rs))
    sup = SrvSupport(name, dds, thash, req, resp)
    with _lock:
        _srvs[name] = sup
    return sup
