"""Astrobee flight modes: gains, tolerances, hard limits and propulsion limits per mode."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import config


@dataclass(frozen=True)
class FlightMode:
    name: str
    speed: int
    control_enabled: bool
    tolerance_pos: float
    tolerance_att: float
    collision_radius: float
    att_kp: np.ndarray
    att_ki: np.ndarray
    omega_kd: np.ndarray
    pos_kp: np.ndarray
    pos_ki: np.ndarray
    vel_kd: np.ndarray
    hard_limit_vel: float
    hard_limit_accel: float
    hard_limit_omega: float
    hard_limit_alpha: float
    max_force: np.ndarray    # N per body axis at this mode's impeller speed
    max_torque: np.ndarray   # N m per body axis


class UnknownFlightMode(ValueError):
    """Raised for a flight-mode name not in config/astrobee.yaml."""


def names() -> list[str]:
    return list(config.astrobee()["flight_modes"])


def get(name: str | None = None) -> FlightMode:
    """The flight mode `name` (default: config's default_flight_mode)."""
    cfg = config.astrobee()
    name = name or cfg["default_flight_mode"]
    modes = cfg["flight_modes"]
    if name not in modes:
        raise UnknownFlightMode(f"unknown flight mode {name!r}; known: {', '.join(modes)}")
    m = modes[name]
    g = m["gains"]
    prop = cfg["propulsion"][m["speed"]]
    arr = lambda v: np.asarray(v, dtype=float)  # noqa: E731
    return FlightMode(
        name=name, speed=int(m["speed"]), control_enabled=bool(m["control_enabled"]),
        tolerance_pos=float(m["tolerance_pos"]), tolerance_att=float(m["tolerance_att"]),
        collision_radius=float(m["collision_radius"]),
        att_kp=arr(g["att_kp"]), att_ki=arr(g["att_ki"]), omega_kd=arr(g["omega_kd"]),
        pos_kp=arr(g["pos_kp"]), pos_ki=arr(g["pos_ki"]), vel_kd=arr(g["vel_kd"]),
        hard_limit_vel=float(m["hard_limit_vel"]), hard_limit_accel=float(m["hard_limit_accel"]),
        hard_limit_omega=float(m["hard_limit_omega"]), hard_limit_alpha=float(m["hard_limit_alpha"]),
        max_force=arr(prop["force"]), max_torque=arr(prop["torque"]),
    )
