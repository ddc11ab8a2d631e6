"""Locating and loading the project's YAML configuration (config/ at the project root).

The directory is $ASTROBEE_CONFIG_DIR when set, else the `config/` folder of the source tree
this package was installed from (editable install or a checkout).
"""
from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import yaml


class ConfigError(RuntimeError):
    """A configuration file is missing or malformed; the message names the file."""


def project_root() -> Path:
    """Root of the source tree (holds config/, astrobee_msgs/)."""
    return Path(__file__).resolve().parents[2]


def msgs_dir() -> Path:
    """The astrobee_msgs interface package (declared to roszen's typestore by the
    `roszen.interfaces` entry point, so no import of this package touches the transport)."""
    return project_root() / "astrobee_msgs"


def config_dir() -> Path:
    env = os.environ.get("ASTROBEE_CONFIG_DIR")
    return Path(env) if env else project_root() / "config"


def load_yaml(path: str | os.PathLike) -> dict[str, Any]:
    """Load a YAML mapping; relative paths are taken inside config_dir()."""
    p = Path(path)
    if not p.is_absolute() and not p.exists():
        p = config_dir() / p
    if not p.exists():
        raise ConfigError(f"config file not found: {p}")
    try:
        data = yaml.safe_load(p.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError(f"config file {p} is not valid YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise ConfigError(f"config file {p} does not hold a mapping")
    return data


@lru_cache(maxsize=None)
def _cached(name: str) -> dict[str, Any]:
    return load_yaml(name)


def iss() -> dict[str, Any]:
    """config/iss.yaml (modules, waypoints, keep-in boxes)."""
    return _cached("iss.yaml")


def astrobee() -> dict[str, Any]:
    """config/astrobee.yaml (mass, inertia, propulsion, flight modes)."""
    return _cached("astrobee.yaml")


def bags() -> dict[str, Any]:
    """config/bags.yaml (CTB sizes, handles, bag-model parameters)."""
    return _cached("bags.yaml")


def controllers() -> dict[str, Any]:
    return _cached("controllers.yaml")


def keep_in_boxes() -> np.ndarray:
    """The keep-in boxes as an (N, 6) array [xmin, ymin, zmin, xmax, ymax, zmax]."""
    return np.array([k["box"] for k in iss()["keep_in"]], dtype=float)


def waypoint(name: str) -> np.ndarray:
    wps = iss()["waypoints"]
    if name not in wps:
        raise ConfigError(f"unknown waypoint {name!r}; known: {', '.join(sorted(wps))}")
    return np.array(wps[name], dtype=float)


def scenario(name: str) -> dict[str, Any]:
    """config/scenarios/<name>.yaml."""
    p = config_dir() / "scenarios" / f"{name}.yaml"
    if not p.exists():
        known = sorted(q.stem for q in (config_dir() / "scenarios").glob("*.yaml"))
        raise ConfigError(f"unknown scenario {name!r}; known: {', '.join(known)}")
    return load_yaml(p)
