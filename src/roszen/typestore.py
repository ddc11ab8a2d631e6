"""The ROS 2 type store: message/service classes, CDR, RIHS01 hashes and definitions.

Types come from interface packages (package.xml + msg/ srv/) registered with
`register_interface_path` or ROSZEN_INTERFACE_PATH, the ones shipped in roszen/interfaces,
and rosbags' ROS 2 Jazzy store (common_interfaces ...). Loading is lazy and thread-safe.
"""
from __future__ import annotations

import os
import re
import sys
import threading
from pathlib import Path
from typing import Any, Callable

from .types import convert as _convert
from .types import rihs as _rihs
from .types.cdr import CdrBackend, MessageDecodeError, MessageEncodeError, make_checker
from .types.cdrgen import make_serializer as make_fast_serializer
from .types.classes import DTYPES, make_class
from .types.spec import InterfaceParseError, MsgSpec, SrvSpec, parse_msg, parse_srv
from .types.spec import Constant, Field, FieldType

__all__ = [
    "MessageDecodeError", "MessageEncodeError", "UnknownTypeError", "InterfaceParseError",
    "register_interface_path", "message_class", "request_class", "response_class",
    "serialize", "deserialize", "serializer", "deserializer", "type_hash", "dds_type_name", "message_definition",
    "to_dict", "from_dict", "to_yaml", "list_types", "is_service", "definition_text",
    "normalize_type_name", "get_spec", "get_service_spec",
]

SHIPPED = Path(__file__).resolve().parent / "interfaces"
ENV_VAR = "ROSZEN_INTERFACE_PATH"


class UnknownTypeError(ValueError):
    """A type name that no registered interface package or built-in store defines."""


_lock = threading.RLock()
_paths: list[Path] = [SHIPPED]
_scanned: set[Path] = set()
_env_seen: str | None = None
_index: dict[str, Path] = {}          # "pkg/msg/Name" | "pkg/srv/Name" -> file
_specs: dict[str, MsgSpec] = {}       # messages incl. pkg/srv/Name_Request/_Response/_Event
_srvs: dict[str, SrvSpec] = {}
_classes: dict[str, type] = {}
_hashes: dict[str, str] = {}
_serializers: dict[str, Callable[[Any], bytes]] = {}
_deserializers: dict[str, Callable[[Any], Any]] = {}
_checkers: dict[str, Any] = {}
_rosbags_defs: dict | None = None
_backend: CdrBackend | None = None


# ---------------------------------------------------------------- registration and lookup

def register_interface_path(path: str | os.PathLike) -> None:
    """Add an interface package directory, or a directory of such packages (parsed lazily)."""
    p = Path(path).expanduser().resolve()
    if not p.is_dir():
        raise ValueError(f"interface path {str(path)!r} is not a directory")
    with _lock:
        if p not in _paths:
            _paths.append(p)


def _package_name(pkg_dir: Path) -> str:
    try:
        text = (pkg_dir / "package.xml").read_text(encoding="utf-8")
        m = re.search(r"<name>\s*([A-Za-z0-9_]+)\s*</name>", text)
        if m:
            return m.group(1)
    except OSError:
        pass
    return pkg_dir.name


def _scan_package(pkg_dir: Path) -> None:
    pkg = _package_name(pkg_dir)
    for kind, ext in (("msg", ".msg"), ("srv", ".srv")):
        d = pkg_dir / kind
        if d.is_dir():
            for f in sorted(d.iterdir()):
                if f.suffix == ext and f.is_file():
                    _index[f"{pkg}/{kind}/{f.stem}"] = f


_entry_points_read = False


def _entry_point_paths() -> list[Path]:
    """Interface directories declared by installed distributions in the `roszen.interfaces`
    entry-point group (a callable returning a path, or a path string attribute)."""
    from importlib.metadata import entry_points
    out = []
    for ep in entry_points(group="roszen.interfaces"):
        try:
            obj = ep.load()
            p = Path(obj() if callable(obj) else obj).expanduser().resolve()
        except Exception:   # a broken declaration must not break every other type
            continue
        if p.is_dir():
            out.append(p)
    return out


def _refresh() -> None:
    """Index the files of paths not scanned yet (called under the lock)."""
    global _env_seen, _entry_points_read
    if not _entry_points_read:
        _entry_points_read = True
        for p in _entry_point_paths():
            if p not in _paths:
                _paths.append(p)
    env = os.environ.get(ENV_VAR, "")
    if env != _env_seen:
        _env_seen = env
        for item in env.split(os.pathsep):
            if item.strip():
                p = Path(item.strip()).expanduser().resolve()
                if p.is_dir() and p not in _paths:
                    _paths.append(p)
    for p in _paths:
        if p in _scanned:
            continue
        _scanned.add(p)
        if (p / "package.xml").is_file():
            _scan_package(p)
        elif p.is_dir():
            for child in sorted(p.iterdir()):
                if child.is_dir() and (child / "package.xml").is_file():
                    _scan_package(child)


def _rosbags() -> dict:
    global _rosbags_defs
    if _rosbags_defs is None:
        from rosbags.typesys import Stores, get_typestore

        _rosbags_defs = dict(get_typestore(Stores.ROS2_JAZZY).fielddefs)
    return _rosbags_defs


def _from_rosbags(name: str, defs: tuple) -> MsgSpec:
    from rosbags.interfaces import Nodetype

    consts, fields = defs

    def ftype(desc: tuple) -> FieldType:
        kind, arg = desc
        if kind == Nodetype.BASE:
            return FieldType(arg[0], "scalar", 0, arg[1] or 0)
        if kind == Nodetype.NAME:
            return FieldType(arg)
        sub = ftype(arg[0])
        if kind == Nodetype.ARRAY:
            return FieldType(sub.base, "array", arg[1], sub.string_bound)
        return FieldType(sub.base, "bseq" if arg[1] else "seq", arg[1], sub.string_bound)

    out = [Field(n, ftype(d)) for n, d in fields if n != "structure_needs_at_least_one_member"]
    return MsgSpec(name, out, [Constant(n, t, v) for n, t, v in consts], None)


def normalize_type_name(name: str) -> str:
    """"pkg/msg/Name", "pkg/Name" or "pkg::msg::dds_::Name_" -> "pkg/msg/Name" (or srv)."""
    if not isinstance(name, str):
        raise TypeError(f"type name must be a str, not {type(name).__name__}")
    n = name.strip()
    if "::" in n:
        parts = n.split("::")
        if len(parts) == 4 and parts[2] == "dds_" and parts[3].endswith("_") and parts[1] in ("msg", "srv"):
            return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"
        if len(parts) == 3 and parts[1] in ("msg", "srv"):
            return "/".join(parts)
        raise UnknownTypeError(f"invalid type name {name!r}")
    parts = n.split("/")
    if len(parts) == 3 and parts[1] in ("msg", "srv", "action") and all(parts):
        return n
    if len(parts) == 2 and all(parts):
        msg, srv = f"{parts[0]}/msg/{parts[1]}", f"{parts[0]}/srv/{parts[1]}"
        with _lock:
            _refresh()
            if msg in _index or msg in _specs or msg in _rosbags():
                return msg
            if srv in _index or srv in _srvs:
                return srv
        return msg
    raise UnknownTypeError(f"invalid type name {name!r} (expected pkg/msg/Name)")


def _service_of(name: str) -> tuple[str, str] | None:
    for suffix in ("_Request", "_Response", "_Event"):
        if name.endswith(suffix) and "/srv/" in name:
            return name[: -len(suffix)], suffix
    return None


def get_service_spec(name: str) -> SrvSpec:
    """The parsed service "pkg/srv/Name"."""
    name = normalize_type_name(name)
    spec = _srvs.get(name)
    if spec is not None:
        return spec
    with _lock:
        spec = _srvs.get(name)
        if spec is not None:
            return spec
        _refresh()
        path = _index.get(name)
        if path is None or "/srv/" not in name:
            raise UnknownTypeError(f"unknown service type {name!r}")
        spec = parse_srv(name, path.read_text(encoding="utf-8"))
        for part in (spec.request, spec.response, spec.event):
            _specs[part.name] = part
        _srvs[name] = spec
        return spec


def get_spec(name: str) -> MsgSpec:
    """The parsed message "pkg/msg/Name" (or a service part "pkg/srv/Name_Request")."""
    spec = _specs.get(name)
    if spec is not None:
        return spec
    name = normalize_type_name(name)
    with _lock:
        spec = _specs.get(name)
        if spec is not None:
            return spec
        _refresh()
        svc = _service_of(name)
        if svc is not None:
            get_service_spec(svc[0])
            return _specs[name]
        path = _index.get(name)
        if path is not None and "/msg/" in name:
            spec = parse_msg(name, path.read_text(encoding="utf-8"))
        elif name in _rosbags():
            spec = _from_rosbags(name, _rosbags()[name])
        else:
            if name in _index or (name.replace("/msg/", "/srv/") in _index):
                raise UnknownTypeError(f"{name!r} is a service, not a message")
            raise UnknownTypeError(f"unknown message type {name!r}")
        _specs[name] = spec
        return spec


# ---------------------------------------------------------------- classes

def message_class(name: str) -> type:
    """The class of message "pkg/msg/Name"; constructible without arguments."""
    cls = _classes.get(name)
    if cls is not None:
        return cls
    with _lock:
        full = normalize_type_name(name)
        cls = _classes.get(full)
        if cls is None:
            cls = _build_class(full, set())
        _classes[name] = cls
        return cls


def _build_class(name: str, active: set[str]) -> type:
    if name in _classes:
        return _classes[name]
    if name in active:
        raise InterfaceParseError(f"recursive message definition through {name!r}")
    active.add(name)
    spec = get_spec(name)
    cls = make_class(spec, lambda sub: _build_class(sub, active))
    _classes[name] = cls
    active.discard(name)
    return cls


def request_class(srv: str) -> type:
    """The Request class of service "pkg/srv/Name"."""
    return message_class(get_service_spec(srv).request.name)


def response_class(srv: str) -> type:
    """The Response class of service "pkg/srv/Name"."""
    return message_class(get_service_spec(srv).response.name)


# ---------------------------------------------------------------- CDR

def _get_backend() -> CdrBackend:
    global _backend
    if _backend is None:
        _backend = CdrBackend()
    return _backend


def _closure(name: str) -> list[str]:
    order: list[str] = []
    stack = [name]
    while stack:
        n = stack.pop()
        if n in order:
            continue
        order.append(n)
        stack.extend(get_spec(n).dependencies())
    return order


def _prepare(name: str) -> str:
    """Register `name` and all it uses with the CDR backend (under the lock); the full name."""
    full = normalize_type_name(name)
    if full in _srvs or (full in _index and "/srv/" in full and _service_of(full) is None):
        raise UnknownTypeError(f"{full!r} is a service: serialize its Request or Response")
    backend = _get_backend()
    for n in _closure(full):
        if n not in backend.store.fielddefs:
            backend.add(get_spec(n), message_class(n))
    return full


def serialize(msg: Any, name: str) -> bytes:
    """CDR little-endian bytes (with the 00 01 00 00 header) of `msg` as type `name`."""
    fn = _serializers.get(name)
    if fn is None:
        fn = _make_serializer(name)
    return fn(msg)


def serializer(name: str) -> Callable[[Any], bytes]:
    """The cached encoder `fn(msg) -> bytes` of type `name` (what `serialize` calls)."""
    fn = _serializers.get(name)
    return fn if fn is not None else _make_serializer(name)


def deserializer(name: str) -> Callable[[Any], Any]:
    """The cached decoder `fn(data) -> msg` of type `name` (what `deserialize` calls)."""
    fn = _deserializers.get(name)
    return fn if fn is not None else _make_deserializer(name)


def _make_serializer(name: str) -> Callable[[Any], bytes]:
    with _lock:
        full = _prepare(name)
        fn = _serializers.get(full)
        if fn is None:
            checker = make_checker(get_spec(full), get_spec, _checkers)
            fast = None
            if sys.byteorder == "little":  # the generated code copies numpy buffers as they are
                fast = make_fast_serializer(get_spec(full), get_spec, DTYPES)
            fn = _get_backend().serializer(full, _convert.coerce, checker, fast)
            _serializers[full] = fn
        _serializers[name] = fn
        return fn


def deserialize(data: bytes | bytearray | memoryview, name: str) -> Any:
    """Decode a CDR payload of type `name`; MessageDecodeError on malformed input."""
    fn = _deserializers.get(name)
    if fn is None:
        fn = _make_deserializer(name)
    return fn(data)


def _make_deserializer(name: str) -> Callable[[Any], Any]:
    with _lock:
        full = _prepare(name)
        fn = _deserializers.get(full)
        if fn is None:
            fn = _get_backend().deserializer(full)
            _deserializers[full] = fn
        _deserializers[name] = fn
        return fn


# ---------------------------------------------------------------- names, hashes, texts

def is_service(name: str) -> bool:
    """True for a service type "pkg/srv/Name" (not its Request/Response parts)."""
    try:
        full = normalize_type_name(name)
    except UnknownTypeError:
        return False
    if "/srv/" not in full or _service_of(full) is not None:
        return False
    with _lock:
        _refresh()
        return full in _index or full in _srvs


def dds_type_name(name: str) -> str:
    """"std_msgs/msg/String" -> "std_msgs::msg::dds_::String_" (services: the service's)."""
    pkg, kind, base = normalize_type_name(name).split("/")
    return f"{pkg}::{kind}::dds_::{base}_"


def type_hash(name: str) -> str:
    """RIHS01 type hash of a message or service (REP 2016, as rosidl computes it)."""
    h = _hashes.get(name)
    if h is not None:
        return h
    with _lock:
        full = normalize_type_name(name)
        if is_service(full):
            h = _rihs.type_hash(_rihs.service_root(get_service_spec(full)), get_spec)
        else:
            h = _rihs.type_hash(get_spec(full), get_spec)
        _hashes[name] = _hashes[full] = h
        return h


def definition_text(name: str) -> str:
    """The .msg/.srv text (generated from the fields for built-in types without a file)."""
    with _lock:
        full = normalize_type_name(name)
        if is_service(full):
            srv = get_service_spec(full)
            if srv.text is not None:
                return srv.text
            return srv.request.definition() + "---\n" + srv.response.definition()
        return get_spec(full).definition()


def _short(name: str) -> str:
    pkg, _, base = name.split("/")
    return f"{pkg}/{base}"


def message_definition(name: str) -> str:
    """The "ros2msg" schema text rosbag2 writes into MCAP bags for a message type."""
    with _lock:
        full = normalize_type_name(name)
        if is_service(full):
            srv = get_service_spec(full)
            roots = [srv.request, srv.response]
            text = definition_text(full)
        else:
            roots = [get_spec(full)]
            text = roots[0].definition()
        seen: set[str] = set()
        out = [text]

        def deps(spec: MsgSpec) -> list[str]:
            return sorted(spec.dependencies(), key=_short)

        def visit(dep: str) -> None:
            spec = get_spec(dep)
            out.append("\n" + "=" * 80 + "\n" + f"MSG: {_short(dep)}\n" + spec.definition())
            for d in deps(spec):
                if d not in seen:
                    seen.add(d)
                    visit(d)

        for root in roots:
            for d in deps(root):
                if d not in seen:
                    seen.add(d)
                    visit(d)
        return "".join(out)


def list_types() -> list[str]:
    """Every known message and service type name."""
    with _lock:
        _refresh()
        names = set(_index) | set(_rosbags())
        names |= {n for n in _specs if _service_of(n) is None}
        return sorted(n for n in names if "/msg/" in n or "/srv/" in n)


# ---------------------------------------------------------------- dict / YAML

def to_dict(msg: Any) -> dict:
    """Plain dict of a message (numpy arrays become lists), as `ros2 topic echo` shows it."""
    return _convert.to_dict(msg)


def from_dict(name: str, data: dict | None) -> Any:
    """A message of type `name` from a dict (missing fields default); ValueError names bad fields."""
    return _convert.from_dict(message_class(name), data)


def to_yaml(msg: Any) -> str:
    """YAML text of a message like `ros2 topic echo` prints it (without the '---')."""
    return _convert.to_yaml(msg)
