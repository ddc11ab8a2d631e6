"""CDR (XCDR1, little endian, encapsulation 00 01 00 00) serializers backed by rosbags' codegen.

Our own message classes are plugged into a private rosbags Typestore, so rosbags' generated
code builds and reads our instances directly.
"""
from __future__ import annotations

from typing import Callable

from rosbags.interfaces import Nodetype
from rosbags.serde import SerdeError
from rosbags.typesys.store import Typestore

from .spec import FieldType, MsgSpec


class MessageDecodeError(ValueError):
    """A payload that is not a valid CDR encoding of the expected type."""


class MessageEncodeError(TypeError):
    """A message object whose field values cannot be encoded as its type."""


MAX_SEQUENCE = 1 << 28


def _desc(t: FieldType) -> tuple:
    base = {"char": "uint8", "byte": "uint8", "wstring": "string"}.get(t.base, t.base)
    if t.is_primitive:
        sub = (Nodetype.BASE, (base, t.string_bound))
    else:
        sub = (Nodetype.NAME, t.base)
    if t.kind == "scalar":
        return sub
    if t.kind == "array":
        return (Nodetype.ARRAY, (sub, t.size))
    return (Nodetype.SEQUENCE, (sub, t.size))


class CdrBackend:
    """Holds one rosbags Typestore filled with our specs and classes."""

    def __init__(self) -> None:
        self.store = Typestore(max_sequence_length=MAX_SEQUENCE)
        self.classes: dict[str, type] = {}

    def add(self, spec: MsgSpec, cls: type) -> None:
        from .classes import attr_name

        fields = [(attr_name(f.name), _desc(f.type)) for f in spec.wire_fields()]
        self.store.fielddefs[spec.name] = ([], fields)
        self.store.types[spec.name] = cls._from_values  # rosbags calls it as cls(*values)
        self.classes[spec.name] = cls

    def serializer(self, name: str, coerce: Callable[[object], object],
                   checker: Callable[[object], bool] | None,
                   fast: Callable[[object], bytes] | None = None) -> Callable[[object], bytes]:
        """Encoder for `name`: `fast` (generated, checks inline) or rosbags' code after `checker`.

        A message the fast path refuses goes once through `coerce` (the validating converter):
        convertible values are sent, anything else raises MessageEncodeError naming the field.
        """
        store = self.store
        msgdef = store.get_msgdef(name)
        getsize, ser, cls = msgdef.getsize_cdr, msgdef.serialize_cdr_le, self.classes[name]

        if fast is None:
            def fast(msg: object) -> bytes:
                if checker is not None and not checker(msg):
                    raise TypeError("field values need conversion")
                size = getsize(0, msg, store)
                buf = bytearray(size + 4)
                buf[1] = 1
                ser(memoryview(buf)[4:], 0, msg, store)
                return bytes(buf)

        def serialize(msg: object) -> bytes:
            try:
                return fast(msg)
            except Exception as exc:  # noqa: BLE001 - retried once with coerced field values
                if not isinstance(msg, cls):
                    raise MessageEncodeError(
                        f"cannot serialize {type(msg).__name__} as {name}") from exc
                try:
                    return fast(coerce(msg))
                except MessageEncodeError:
                    raise
                except Exception as exc2:  # noqa: BLE001
                    raise MessageEncodeError(f"cannot serialize {name}: {exc2}") from exc2

        return serialize

    def deserializer(self, name: str) -> Callable[[bytes], object]:
        store = self.store
        msgdef = store.get_msgdef(name)
        des, cls = msgdef.deserialize_cdr_le, msgdef.cls

        def deserialize(data: bytes | bytearray | memoryview) -> object:
            n = len(data)
            if n < 4:
                raise MessageDecodeError(f"{name}: payload of {n} bytes is shorter than the CDR header")
            head = bytes(data[:2])
            if head != b"\x00\x01":
                if head == b"\x00\x00":
                    raise MessageDecodeError(f"{name}: big-endian CDR is not supported")
                raise MessageDecodeError(f"{name}: bad CDR encapsulation {head.hex()}")
            try:
                msg, pos = des(memoryview(bytearray(data))[4:], 0, cls, store)
            except (SerdeError, Exception) as exc:  # noqa: BLE001 - any decoder failure is bad input
                raise MessageDecodeError(f"{name}: malformed CDR payload ({exc})") from exc
            if pos + 4 + 3 < n:
                raise MessageDecodeError(f"{name}: {n - 4 - pos} trailing bytes after the message")
            return msg

        return deserialize


def make_checker(spec: MsgSpec, lookup: Callable[[str], MsgSpec],
                 cache: dict[str, Callable[[object], bool] | None]) -> Callable[[object], bool] | None:
    """A fast check that every numpy field has the exact dtype and every bound is respected.

    rosbags' codegen copies array bytes as they are (an int64 array in a float64 field would be
    sent as garbage) and ignores bounds; a failed check sends the message through the
    validating converter instead. None when the type has nothing to check.
    """
    from .classes import DTYPES, attr_name

    if spec.name in cache:
        return cache[spec.name]
    cache[spec.name] = None  # provisional (no recursive types in ROS, but be safe)
    ns: dict[str, object] = {"_nd": __import__("numpy").ndarray}
    lines: list[str] = []
    for i, f in enumerate(spec.fields):
        t, a = f.type, attr_name(f.name)
        if t.is_primitive:
            if t.base in DTYPES and t.is_container:
                ns[f"_t{i}"] = DTYPES[t.base]
                lines.append(f"    v = m.{a}")
                lines.append(f"    if type(v) is not _nd or v.dtype != _t{i} or v.ndim != 1: return False")
                if t.kind == "bseq":
                    lines.append(f"    if len(v) > {t.size}: return False")
            elif t.base in ("string", "wstring") and (t.string_bound or t.kind == "bseq"):
                lines.append(f"    v = m.{a}")
                if t.kind == "bseq":
                    lines.append(f"    if len(v) > {t.size}: return False")
                if t.string_bound:
                    if t.kind == "scalar":
                        lines.append(f"    if len(v) > {t.string_bound}: return False")
                    else:
                        lines.append(f"    if any(len(x) > {t.string_bound} for x in v): return False")
            continue
        sub = make_checker(lookup(t.base), lookup, cache)
        if sub is None and t.kind != "bseq":
            continue
        ns[f"_c{i}"] = sub
        lines.append(f"    v = m.{a}")
        if t.kind == "bseq":
            lines.append(f"    if len(v) > {t.size}: return False")
        if sub is not None:
            if t.kind == "scalar":
                lines.append(f"    if not _c{i}(v): return False")
            else:
                lines.append(f"    for x in v:")
                lines.append(f"        if not _c{i}(x): return False")
    if not lines:
        cache[spec.name] = None
        return None
    code = "def check(m):\n" + "\n".join(lines) + "\n    return True\n"
    exec(compile(code, f"<roszen check {spec.name}>", "exec"), ns)  # noqa: S102
    cache[spec.name] = ns["check"]
    return ns["check"]
