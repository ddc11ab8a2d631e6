"""rmw_zenoh (Jazzy) wire details: key expressions, liveliness tokens, GIDs, attachments."""
from __future__ import annotations

import struct
import time
from dataclasses import dataclass
from typing import Callable, Optional

import xxhash

from .qos import QoSProfile

ADMIN_SPACE = "@ros2_lv"
NODE, PUB, SUB, SERVICE, CLIENT = "NN", "MP", "MS", "SS", "SC"
ATTACHMENT_SIZE = 33
_ATT = struct.Struct("<qqB16s")


def mangle(name: str) -> str:
    """Every '/' becomes '%'; an empty name becomes '%' (zenoh keys cannot hold '//')."""
    return name.replace("/", "%") if name else "%"


def demangle(name: str) -> str:
    return name.replace("%", "/")


def topic_keyexpr(domain_id: int, fq_name: str, dds_type: str, type_hash: str) -> str:
    """`<domain>/<fq name without leading slash>/<dds type>/<RIHS01 hash>`."""
    return f"{domain_id}/{fq_name.lstrip('/')}/{dds_type}/{type_hash}"


def node_token(domain_id: int, zid: str, nid: int, enclave: str, namespace: str, name: str) -> str:
    return f"{ADMIN_SPACE}/{domain_id}/{zid}/{nid}/{nid}/{NODE}/{mangle(enclave)}/{mangle(namespace)}/{mangle(name)}"


def endpoint_token(domain_id: int, zid: str, nid: int, eid: int, kind: str, enclave: str,
                   namespace: str, node_name: str, fq_name: str, dds_type: str, type_hash: str,
                   qos: QoSProfile) -> str:
    return (f"{ADMIN_SPACE}/{domain_id}/{zid}/{nid}/{eid}/{kind}/{mangle(enclave)}/{mangle(namespace)}/"
            f"{mangle(node_name)}/{mangle(fq_name)}/{mangle(dds_type)}/{mangle(type_hash)}/{qos.to_token()}")


def gid_of(token: str) -> bytes:
    """GID: XXH3-128 of the token string, low 64 bits LE then high 64 bits LE."""
    return xxhash.xxh3_128_intdigest(token.encode()).to_bytes(16, "little")


_ATT_HEAD = struct.Struct("<qq")


def attachment_maker(gid: bytes) -> "Callable[[int], bytes]":
    """`f(seq)`: the attachment of one publisher (GID part built once, timestamp = now)."""
    if len(gid) != 16:
        raise ValueError(f"GID must be 16 bytes, got {len(gid)}")
    tail, head, now = b"\x10" + bytes(gid), _ATT_HEAD.pack, time.time_ns
    return lambda seq: head(seq, now()) + tail


def make_attachment(seq: int, gid: bytes, timestamp_ns: Optional[int] = None) -> bytes:
    """33 bytes: int64 seq, int64 source timestamp ns, 0x10, 16-byte GID."""
    return _ATT.pack(seq, time.time_ns() if timestamp_ns is None else timestamp_ns, 16, gid)


@dataclass(frozen=True)
class Attachment:
    sequence_number: int
    source_timestamp: int
    gid: bytes


def parse_attachment(data: bytes) -> Attachment:
    """Decode an rmw_zenoh attachment; raise ValueError if it is not one."""
    if len(data) != ATTACHMENT_SIZE:
        raise ValueError(f"attachment is {len(data)} bytes, expected {ATTACHMENT_SIZE}")
    seq, ts, n, gid = _ATT.unpack(data)
    if n != 16:
        raise ValueError(f"attachment GID length byte is {n}, expected 16")
    return Attachment(seq, ts, gid)


@dataclass(frozen=True)
class Entity:
    """One parsed liveliness token."""
    token: str
    domain_id: int
    zid: str
    nid: int
    eid: int
    kind: str
    enclave: str
    namespace: str
    node_name: str
    name: str = ""          # fully qualified topic/service name
    dds_type: str = ""
    type_hash: str = ""
    qos: Optional[QoSProfile] = None

    @property
    def node_key(self) -> tuple:
        return (self.zid, self.nid)

    @property
    def node_fqn(self) -> str:
        return (self.namespace.rstrip("/") + "/" + self.node_name) if self.namespace != "/" else "/" + self.node_name

    @property
    def ros_type(self) -> str:
        return dds_to_ros_type(self.dds_type)

    @property
    def gid(self) -> bytes:
        return gid_of(self.token)


def parse_token(token: str) -> Entity:
    """Parse a `@ros2_lv/...` token (ValueError if malformed)."""
    parts = token.split("/")
    if len(parts) < 9 or parts[0] != ADMIN_SPACE:
        raise ValueError(f"not an rmw_zenoh liveliness token: {token!r}")
    domain, zid, nid, eid, kind = int(parts[1]), parts[2], int(parts[3]), int(parts[4]), parts[5]
    enclave, ns, name = demangle(parts[6]), demangle(parts[7]), demangle(parts[8])
    if kind == NODE:
        return Entity(token, domain, zid, nid, eid, kind, enclave, ns or "/", name)
    if kind not in (PUB, SUB, SERVICE, CLIENT) or len(parts) < 13:
        raise ValueError(f"bad endpoint token: {token!r}")
    return Entity(token, domain, zid, nid, eid, kind, enclave, ns or "/", name,
                  demangle(parts[9]), demangle(parts[10]), demangle(parts[11]),
                  QoSProfile.from_token(parts[12]))


def ros_to_dds_type(ros_type: str) -> str:
    """`pkg/msg/Name` -> `pkg::msg::dds_::Name_`."""
    pkg, kind, name = ros_type.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def dds_to_ros_type(dds: str) -> str:
    """`pkg::msg::dds_::Name_` -> `pkg/msg/Name` (best effort for unusual names)."""
    parts = dds.split("::")
    if len(parts) == 4 and parts[2] == "dds_" and parts[3].endswith("_"):
        return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"
    return dds.replace("::", "/")
