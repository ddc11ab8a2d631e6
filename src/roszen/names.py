"""ROS 2 name validation, expansion (relative, absolute, ~ private) and remapping."""
from __future__ import annotations

import re
from typing import Mapping

_TOKEN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_NODE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


class InvalidNameError(ValueError):
    """A node, namespace, topic or service name breaks the ROS 2 naming rules."""


def validate_node_name(name: str) -> str:
    if not _NODE.match(name or ""):
        raise InvalidNameError(f"invalid node name {name!r}: letters, digits and '_' only, not starting with a digit")
    return name


def normalize_namespace(ns: str) -> str:
    """'' or '/' -> '/', 'a/b' -> '/a/b', trailing '/' removed; validated."""
    ns = (ns or "").strip()
    if ns in ("", "/"):
        return "/"
    if not ns.startswith("/"):
        ns = "/" + ns
    ns = ns.rstrip("/")
    for tok in ns[1:].split("/"):
        if not _TOKEN.match(tok):
            raise InvalidNameError(f"invalid namespace {ns!r} (bad token {tok!r})")
    return ns


def expand_name(name: str, node_name: str, namespace: str) -> str:
    """Expand a topic/service name to its fully qualified form (rcl_expand_topic_name rules)."""
    if not name:
        raise InvalidNameError("empty topic/service name")
    ns = normalize_namespace(namespace)
    if name.startswith("~"):
        base = (ns.rstrip("/") + "/" + node_name)
        rest = name[1:]
        if rest and not rest.startswith("/"):
            raise InvalidNameError(f"invalid private name {name!r}: '~' must be followed by '/'")
        fq = base + rest
    elif name.startswith("/"):
        fq = name
    else:
        fq = ns.rstrip("/") + "/" + name
    fq = fq.replace("{node}", node_name).replace("{ns}", ns).replace("{namespace}", ns)
    if fq != "/" and fq.endswith("/"):
        raise InvalidNameError(f"invalid name {name!r}: must not end with '/'")
    if "//" in fq:
        raise InvalidNameError(f"invalid name {name!r}: contains '//'")
    for tok in fq[1:].split("/"):
        if not _TOKEN.match(tok):
            raise InvalidNameError(f"invalid name {name!r} (bad token {tok!r})")
    return fq


def apply_remap(fq: str, remaps: Mapping[str, str], node_name: str, namespace: str) -> str:
    """Apply `from:=to` remap rules (both sides expanded in the node's context)."""
    for src, dst in remaps.items():
        try:
            if expand_name(src, node_name, namespace) == fq:
                return expand_name(dst, node_name, namespace)
        except InvalidNameError:
            continue
    return fq
