"""`--ros-args` command-line parsing and ROS 2 parameter YAML files."""
from __future__ import annotations

import fnmatch
import re
from dataclasses import dataclass, field
from typing import Any, Optional, Sequence

from . import yamltext


class RosArgsError(ValueError):
    """A malformed `--ros-args` argument or parameter file."""


@dataclass
class RosArgs:
    """What `--ros-args` carried; node-scoped entries are kept with their node name."""
    params: list = field(default_factory=list)          # (node or None, name, value) in order
    params_files: list = field(default_factory=list)
    remaps: list = field(default_factory=list)          # (node or None, from, to)
    namespace: Optional[str] = None
    node_name: Optional[str] = None
    log_level: Optional[str] = None
    enclave: Optional[str] = None

    def remaps_for(self, node_name: str) -> dict:
        return {src: dst for node, src, dst in self.remaps if node in (None, node_name)}


def parse_value(text: str) -> Any:
    """Parse a `-p name:=value` value the way rcl does (as a YAML scalar or list)."""
    try:
        return yamltext.load(text) if text != "" else ""
    except yamltext.YamlTooDeep as exc:
        raise RosArgsError(f"parameter value: {exc}") from None
    except yamltext.YamlError:
        return text


def _split_rule(rule: str, flag: str) -> tuple:
    if ":=" not in rule:
        raise RosArgsError(f"{flag} expects name:=value, got {rule!r}")
    lhs, value = rule.split(":=", 1)
    node = None
    if ":" in lhs:
        node, lhs = lhs.split(":", 1)
    if not lhs:
        raise RosArgsError(f"{flag} has an empty name in {rule!r}")
    return node, lhs, value


def parse_args(argv: Optional[Sequence[str]]) -> tuple:
    """Split argv into (user args, RosArgs). Several `--ros-args` sections are allowed."""
    ros = RosArgs()
    user: list = []
    if not argv:
        return user, ros
    argv = list(argv)
    i, in_ros = 0, False
    while i < len(argv):
        a = argv[i]
        if a == "--ros-args":
            in_ros = True
            i += 1
            continue
        if not in_ros:
            user.append(a)
            i += 1
            continue
        if a == "--":
            in_ros = False
            i += 1
            continue

        def nxt() -> str:
            if i + 1 >= len(argv):
                raise RosArgsError(f"{a} needs an argument")
            return argv[i + 1]
        if a in ("-p", "--param"):
            node, name, value = _split_rule(nxt(), a)
            ros.params.append((node, name, parse_value(value)))
            i += 2
        elif a in ("-r", "--remap"):
            node, src, dst = _split_rule(nxt(), a)
            if src == "__ns":
                ros.namespace = dst
            elif src in ("__node", "__name"):
                ros.node_name = dst
            else:
                ros.remaps.append((node, src, dst))
            i += 2
        elif a == "--params-file":
            ros.params_files.append(nxt())
            i += 2
        elif a == "--log-level":
            v = nxt()
            ros.log_level = v.split(":=", 1)[-1]
            i += 2
        elif a in ("-e", "--enclave"):
            ros.enclave = nxt()
            i += 2
        elif a in ("--disable-rosout-logs", "--enable-rosout-logs", "--disable-stdout-logs",
                   "--enable-stdout-logs", "--disable-external-lib-logs"):
            i += 1
        else:
            raise RosArgsError(f"unknown --ros-args argument {a!r}")
    return user, ros


def remove_ros_args(argv: Sequence[str]) -> list:
    """argv without its `--ros-args ... [--]` sections (like rclpy.utilities.remove_ros_args)."""
    return parse_args(argv)[0]


def _flatten(prefix: str, value: Any, out: dict) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            _flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    else:
        out[prefix] = value


def _node_matches(pattern: str, fqn: str, node_name: str) -> bool:
    if pattern in ("/**", "**"):
        return True
    if not pattern.startswith("/"):
        return pattern == node_name or fnmatch.fnmatchcase(node_name, pattern) or pattern == fqn.lstrip("/")
    rx = re.escape(pattern).replace(r"/\*\*", "(/[^/]+)*").replace(r"\*", "[^/]*")
    return re.fullmatch(rx, fqn) is not None


def load_params_file(path: str, node_name: str, namespace: str) -> dict:
    """Parameters for one node from a ROS 2 YAML file (`node: ros__parameters: {...}`, `/**` etc)."""
    try:
        with open(path) as f:
            doc = yamltext.load(f, f"parameter file {path}") or {}
    except OSError as e:
        raise RosArgsError(f"cannot read parameter file {path}: {e}") from e
    except yamltext.YamlError as e:
        raise RosArgsError(str(e)) from None
    if not isinstance(doc, dict):
        raise RosArgsError(f"parameter file {path}: top level must be a mapping of node names")
    ns = namespace.rstrip("/")
    fqn = f"{ns}/{node_name}"
    out: dict = {}
    for key, body in doc.items():
        key = str(key)
        if not isinstance(body, dict):
            raise RosArgsError(f"parameter file {path}: entry {key!r} must be a mapping")
        if "ros__parameters" not in body:
            # namespace nesting: {ns: {node: {ros__parameters: ...}}}
            for sub, subbody in body.items():
                if isinstance(subbody, dict) and "ros__parameters" in subbody:
                    pat = f"/{key.strip('/')}/{str(sub).strip('/')}"
                    if _node_matches(pat, fqn, node_name):
                        _flatten("", subbody["ros__parameters"] or {}, out)
            continue
        if _node_matches(key, fqn, node_name):
            _flatten("", body["ros__parameters"] or {}, out)
    return out
