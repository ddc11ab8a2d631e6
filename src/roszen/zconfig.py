"""Zenoh session/router configuration the way rmw_zenoh builds it, honouring the env vars."""
from __future__ import annotations

import json
import os
from typing import Mapping, Optional

import zenoh

DEFAULT_ROUTER_PORT = 7447


class ConfigError(RuntimeError):
    """A bad ZENOH_* configuration (file missing, override malformed)."""


def domain_id(env: Optional[Mapping[str, str]] = None) -> int:
    """ROS_DOMAIN_ID as an int (default 0)."""
    env = os.environ if env is None else env
    text = env.get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return 0
    try:
        value = int(text)
    except ValueError:
        raise ConfigError(f"ROS_DOMAIN_ID must be an integer, got {text!r}") from None
    if value < 0:
        raise ConfigError(f"ROS_DOMAIN_ID must be >= 0, got {value}")
    return value


def parse_override(text: str) -> list:
    """`key=value;key2=value2` (values are JSON5) -> [(key, value)]."""
    out = []
    for part in (text or "").split(";"):
        part = part.strip()
        if not part:
            continue
        if "=" not in part:
            raise ConfigError(f"ZENOH_CONFIG_OVERRIDE entry {part!r} is not key=value")
        key, value = part.split("=", 1)
        key, value = key.strip(), value.strip()
        if not key or not value:
            raise ConfigError(f"ZENOH_CONFIG_OVERRIDE entry {part!r} has an empty key or value")
        out.append((key, value))
    return out


def _apply(cfg: "zenoh.Config", key: str, value: str) -> None:
    try:
        cfg.insert_json5(key, value)
    except Exception as e:
        raise ConfigError(f"cannot set zenoh config {key}={value}: {e}") from e


def _from_file(path: str, what: str) -> "zenoh.Config":
    if not os.path.isfile(path):
        raise ConfigError(f"{what} points to {path!r}, which is not a file")
    try:
        return zenoh.Config.from_file(path)
    except Exception as e:
        raise ConfigError(f"{what} file {path} is not a valid zenoh config: {e}") from e


def session_config(env: Optional[Mapping[str, str]] = None) -> "zenoh.Config":
    """Peer session: connect tcp/localhost:7447, listen tcp/localhost:0, no multicast, gossip on."""
    env = os.environ if env is None else env
    uri = env.get("ZENOH_SESSION_CONFIG_URI", "").strip()
    if uri:
        cfg = _from_file(uri, "ZENOH_SESSION_CONFIG_URI")
    else:
        cfg = zenoh.Config()
        for k, v in (("mode", '"peer"'),
                     ("connect/endpoints", f'["tcp/localhost:{DEFAULT_ROUTER_PORT}"]'),
                     ("listen/endpoints", '["tcp/localhost:0"]'),
                     ("scouting/multicast/enabled", "false"),
                     ("scouting/gossip/enabled", "true")):
            _apply(cfg, k, v)
    for k, v in parse_override(env.get("ZENOH_CONFIG_OVERRIDE", "")):
        _apply(cfg, k, v)
    return cfg


def router_config(listen: Optional[str] = None, env: Optional[Mapping[str, str]] = None) -> "zenoh.Config":
    """Router: loopback tcp/127.0.0.1:7447 by default (or ZENOH_ROUTER_CONFIG_URI), no multicast."""
    env = os.environ if env is None else env
    uri = env.get("ZENOH_ROUTER_CONFIG_URI", "").strip()
    if uri:
        cfg = _from_file(uri, "ZENOH_ROUTER_CONFIG_URI")
    else:
        cfg = zenoh.Config()
        for k, v in (("mode", '"router"'),
                     ("listen/endpoints", f'["tcp/127.0.0.1:{DEFAULT_ROUTER_PORT}"]'),
                     ("scouting/multicast/enabled", "false"),
                     ("scouting/gossip/enabled", "true")):
            _apply(cfg, k, v)
    if listen:
        _apply(cfg, "listen/endpoints", json.dumps([e.strip() for e in listen.split(",") if e.strip()]))
    for k, v in parse_override(env.get("ZENOH_CONFIG_OVERRIDE", "")):
        if k.startswith("connect/"):
            continue  # a node-facing override must not make the router dial itself
        _apply(cfg, k, v)
    return cfg
