"""RIHS01 type hashes (REP 2016): sha256 over rosidl's JSON type description.

rosidl maps .msg `char` to uint8 (and `byte` to octet/BYTE); default values and constants are
not part of the hashed description; an empty struct has the dummy uint8 member.
"""
from __future__ import annotations

import hashlib
import json
from typing import Callable

from .spec import FieldType, MsgSpec, SrvSpec

TYPE_IDS = {
    "nested": 1, "int8": 2, "uint8": 3, "int16": 4, "uint16": 5, "int32": 6, "uint32": 7,
    "int64": 8, "uint64": 9, "float32": 10, "float64": 11, "char": 3, "wchar": 14,
    "bool": 15, "byte": 16, "string": 17, "wstring": 18,
}
BOUNDED = {"string": 21, "wstring": 22}
KIND_OFFSET = {"scalar": 0, "array": 48, "bseq": 96, "seq": 144}


def field_type_dict(ftype: FieldType) -> dict:
    """The type_description_interfaces/FieldType of one field, as a dict in rosidl key order."""
    if ftype.is_primitive:
        tid = BOUNDED[ftype.base] if ftype.string_bound else TYPE_IDS[ftype.base]
        nested = ""
    else:
        tid = TYPE_IDS["nested"]
        nested = ftype.base
    return {
        "type_id": tid + KIND_OFFSET[ftype.kind],
        "capacity": ftype.size if ftype.kind != "seq" else 0,
        "string_capacity": ftype.string_bound,
        "nested_type_name": nested,
    }


def individual(spec: MsgSpec) -> dict:
    return {
        "type_name": spec.name,
        "fields": [{"name": f.name, "type": field_type_dict(f.type)} for f in spec.wire_fields()],
    }


def type_description(root: MsgSpec, lookup: Callable[[str], MsgSpec]) -> dict:
    """Hashable type description: the root plus every referenced type sorted by name."""
    refs: dict[str, dict] = {}
    stack = list(root.dependencies())
    while stack:
        name = stack.pop()
        if name in refs or name == root.name:
            continue
        spec = lookup(name)
        refs[name] = individual(spec)
        stack.extend(spec.dependencies())
    return {
        "type_description": individual(root),
        "referenced_type_descriptions": [refs[k] for k in sorted(refs)],
    }


def service_root(srv: SrvSpec) -> MsgSpec:
    """The service's own struct: request_message, response_message, event_message."""
    from .spec import Field

    return MsgSpec(srv.name, [
        Field("request_message", FieldType(srv.request.name)),
        Field("response_message", FieldType(srv.response.name)),
        Field("event_message", FieldType(srv.event.name)),
    ])


def hash_description(desc: dict) -> str:
    text = json.dumps(desc, separators=(", ", ": "), ensure_ascii=True)
    return "RIHS01_" + hashlib.sha256(text.encode()).hexdigest()


def type_hash(root: MsgSpec, lookup: Callable[[str], MsgSpec]) -> str:
    return hash_description(type_description(root, lookup))
