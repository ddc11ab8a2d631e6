"""Message and service specifications: the parsed form of .msg/.srv texts (rosidl semantics).

Every other part of the typestore (classes, CDR, hashes, definitions, YAML) works from these.
"""
from __future__ import annotations

import ast
import re
from dataclasses import dataclass, field

PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
}
INT_RANGES = {
    "byte": (0, 255), "char": (0, 255), "int8": (-128, 127), "uint8": (0, 255),
    "int16": (-(1 << 15), (1 << 15) - 1), "uint16": (0, (1 << 16) - 1),
    "int32": (-(1 << 31), (1 << 31) - 1), "uint32": (0, (1 << 32) - 1),
    "int64": (-(1 << 63), (1 << 63) - 1), "uint64": (0, (1 << 64) - 1),
}
FLOATS = {"float32", "float64"}
STRINGS = {"string", "wstring"}
EMPTY_MEMBER = "structure_needs_at_least_one_member"

_NAME_RE = re.compile(r"^[a-zA-Z][a-zA-Z0-9_]*$")
_TYPE_RE = re.compile(
    r"^(?P<base>[a-zA-Z][a-zA-Z0-9_]*(?:/[a-zA-Z][a-zA-Z0-9_]*){0,2})"
    r"(?:<=(?P<sbound>\d+))?"
    r"(?:\[(?P<arr>(?:<=)?\d*)\])?$"
)


class InterfaceParseError(ValueError):
    """A .msg/.srv text that does not follow the ROS 2 interface grammar."""


@dataclass(frozen=True)
class FieldType:
    """Type of one field: base type plus container kind (scalar, array[N], seq, seq[<=N])."""

    base: str              # primitive name, or full message name "pkg/msg/Name"
    kind: str = "scalar"   # "scalar" | "array" | "bseq" | "seq"
    size: int = 0          # array length or sequence bound
    string_bound: int = 0  # string<=N

    @property
    def is_primitive(self) -> bool:
        return self.base in PRIMITIVES

    @property
    def is_container(self) -> bool:
        return self.kind != "scalar"

    def text(self, context_pkg: str | None = None) -> str:
        """The type as written in a .msg file ("pkg/Name" for messages)."""
        if self.is_primitive:
            base = self.base + (f"<={self.string_bound}" if self.string_bound else "")
        else:
            pkg, _, name = self.base.split("/")
            base = name if pkg == context_pkg else f"{pkg}/{name}"
        if self.kind == "array":
            return f"{base}[{self.size}]"
        if self.kind == "bseq":
            return f"{base}[<={self.size}]"
        if self.kind == "seq":
            return f"{base}[]"
        return base


@dataclass
class Field:
    name: str
    type: FieldType
    default: object = None  # python value from the .msg default, or None


@dataclass
class Constant:
    name: str
    base: str
    value: object


@dataclass
class MsgSpec:
    """One message type (also the Request/Response/Event parts of a service)."""

    name: str                  # "pkg/msg/Name" or "pkg/srv/Name_Request"
    fields: list[Field]
    constants: list[Constant] = field(default_factory=list)
    text: str | None = None    # the .msg text (None: generated from the fields)

    @property
    def package(self) -> str:
        return self.name.split("/")[0]

    def wire_fields(self) -> list[Field]:
        """Fields as on the wire and in the type description (rosidl adds a dummy uint8)."""
        return self.fields or [Field(EMPTY_MEMBER, FieldType("uint8"), 0)]

    def dependencies(self) -> list[str]:
        """Full names of the message types used by the fields, in field order, unique."""
        out: list[str] = []
        for f in self.fields:
            if not f.type.is_primitive and f.type.base not in out:
                out.append(f.type.base)
        return out

    def definition(self) -> str:
        """The .msg text, or one generated from the spec when the original is not known."""
        if self.text is not None:
            return self.text
        lines = [f"{c.base} {c.name}={_value_text(c.value)}" for c in self.constants]
        for f in self.fields:
            line = f"{f.type.text(self.package)} {f.name}"
            if f.default is not None:
                line += f" {_value_text(f.default)}"
            lines.append(line)
        return "\n".join(lines) + ("\n" if lines else "")


@dataclass
class SrvSpec:
    name: str                  # "pkg/srv/Name"
    request: MsgSpec
    response: MsgSpec
    event: MsgSpec
    text: str | None = None


def _value_text(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value_text(v) for v in value) + "]"
    return str(value)


def _strip_comment(line: str) -> str:
    """Drop a '#' comment that is not inside a quoted string."""
    quote = None
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch == "#":
            return line[:i]
    return line


def parse_type(token: str, package: str) -> FieldType:
    """Parse a .msg type token such as "float64[3]", "string<=8[<=2]", "geometry_msgs/Pose[]"."""
    m = _TYPE_RE.match(token)
    if not m:
        raise InterfaceParseError(f"invalid type {token!r}")
    base, sbound, arr = m.group("base"), m.group("sbound"), m.group("arr")
    parts = base.split("/")
    if len(parts) == 1 and base in PRIMITIVES:
        pass
    elif len(parts) == 1:
        if base in ("time", "duration"):
            base = f"builtin_interfaces/msg/{base.capitalize()}"
        else:
            base = f"{package}/msg/{base}"
    elif len(parts) == 2:
        base = f"{parts[0]}/msg/{parts[1]}"
    elif parts[1] not in ("msg", "srv"):
        raise InterfaceParseError(f"invalid type {token!r}")
    if sbound is not None and base not in STRINGS:
        raise InterfaceParseError(f"only strings can be bounded: {token!r}")
    sb = int(sbound) if sbound else 0
    if arr is None:
        return FieldType(base, "scalar", 0, sb)
    if arr == "":
        return FieldType(base, "seq", 0, sb)
    if arr.startswith("<="):
        if arr == "<=":
            raise InterfaceParseError(f"invalid bound in {token!r}")
        return FieldType(base, "bseq", int(arr[2:]), sb)
    return FieldType(base, "array", int(arr), sb)


def parse_value(text: str, ftype: FieldType, what: str) -> object:
    """Parse a constant or default value written in a .msg file."""
    text = text.strip()
    if ftype.is_container:
        try:
            items = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            inner = text.strip()
            if not (inner.startswith("[") and inner.endswith("]")):
                raise InterfaceParseError(f"{what}: invalid array value {text!r}") from None
            items = [s for s in inner[1:-1].split(",") if s.strip()]
            scalar = FieldType(ftype.base, "scalar", 0, ftype.string_bound)
            return [parse_value(str(s), scalar, what) for s in items]
        if not isinstance(items, (list, tuple)):
            raise InterfaceParseError(f"{what}: expected an array value, got {text!r}")
        scalar = FieldType(ftype.base, "scalar", 0, ftype.string_bound)
        return [parse_value(repr(v) if isinstance(v, str) else str(v), scalar, what) for v in items]
    base = ftype.base
    if base == "bool":
        low = text.lower()
        if low in ("true", "1"):
            return True
        if low in ("false", "0"):
            return False
        raise InterfaceParseError(f"{what}: invalid bool {text!r}")
    if base in STRINGS:
        if len(text) >= 2 and text[0] == text[-1] and text[0] in "\"'":
            try:
                return ast.literal_eval(text)
            except (ValueError, SyntaxError):
                return text[1:-1]
        return text
    if base in FLOATS:
        try:
            return float(text)
        except ValueError:
            raise InterfaceParseError(f"{what}: invalid float {text!r}") from None
    if base in INT_RANGES:
        try:
            value = int(text, 0)
        except ValueError:
            raise InterfaceParseError(f"{what}: invalid integer {text!r}") from None
        lo, hi = INT_RANGES[base]
        if not lo <= value <= hi:
            raise InterfaceParseError(f"{what}: {value} out of range for {base}")
        return value
    raise InterfaceParseError(f"{what}: a {base} field cannot have a default value")


def parse_msg(name: str, text: str) -> MsgSpec:
    """Parse a .msg text into a MsgSpec for the full type name "pkg/msg/Name"."""
    package = name.split("/")[0]
    fields: list[Field] = []
    constants: list[Constant] = []
    seen: set[str] = set()
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = _strip_comment(raw).strip()
        if not line:
            continue
        where = f"{name} line {lineno}"
        parts = line.split(None, 1)
        if len(parts) < 2:
            raise InterfaceParseError(f"{where}: expected '<type> <name>', got {raw.strip()!r}")
        type_token, rest = parts
        ftype = parse_type(type_token, package)
        if "=" in rest.split(None, 1)[0] or re.match(r"^[A-Za-z0-9_]+\s*=", rest):
            cname, _, value = rest.partition("=")
            cname = cname.strip()
            if ftype.is_container or not ftype.is_primitive:
                raise InterfaceParseError(f"{where}: constants must be primitive scalars")
            if not _NAME_RE.match(cname):
                raise InterfaceParseError(f"{where}: invalid constant name {cname!r}")
            if ftype.base in STRINGS:
                vtext = value.strip()
            else:
                vtext = value.strip()
            constants.append(Constant(cname, ftype.base, parse_value(vtext, ftype, where)))
            continue
        nparts = rest.split(None, 1)
        fname = nparts[0]
        if not _NAME_RE.match(fname):
            raise InterfaceParseError(f"{where}: invalid field name {fname!r}")
        if fname in seen:
            raise InterfaceParseError(f"{where}: duplicate field {fname!r}")
        seen.add(fname)
        default = None
        if len(nparts) > 1:
            if not ftype.is_primitive:
                raise InterfaceParseError(f"{where}: nested fields cannot have defaults")
            default = parse_value(nparts[1], ftype, where)
        fields.append(Field(fname, ftype, default))
    return MsgSpec(name, fields, constants, text)


SRV_SEPARATOR = re.compile(r"^---\s*$", re.MULTILINE)


def parse_srv(name: str, text: str) -> SrvSpec:
    """Parse a .srv text ("request --- response") for the full service name "pkg/srv/Name"."""
    parts = SRV_SEPARATOR.split(text)
    if len(parts) != 2:
        raise InterfaceParseError(f"{name}: a .srv needs exactly one '---' separator line")
    req_text, resp_text = parts
    if resp_text.startswith("\n"):
        resp_text = resp_text[1:]
    request = parse_msg(f"{name}_Request", req_text)
    response = parse_msg(f"{name}_Response", resp_text)
    event = event_spec(name)
    return SrvSpec(name, request, response, event, text)


def event_spec(name: str) -> MsgSpec:
    """The Event message rosidl generates for every service (REP 2016 / service introspection)."""
    return MsgSpec(f"{name}_Event", [
        Field("info", FieldType("service_msgs/msg/ServiceEventInfo")),
        Field("request", FieldType(f"{name}_Request", "bseq", 1)),
        Field("response", FieldType(f"{name}_Response", "bseq", 1)),
    ])
