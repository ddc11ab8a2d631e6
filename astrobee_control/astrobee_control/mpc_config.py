"""The sampling MPC's parameters (MpcConfig: sampling, horizon, cost weights, attitude mode),
validated, and what one replan decides (Decision)."""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from .reference import SampledTrajectory

MODELS = ("reduced", "pybullet")        # the rollout models a `model` parameter names


@dataclass
class MpcConfig:
    """The MPC's parameters (also the node's ROS parameters of the same names)."""

    samples: int = 128
    horizon: float = 5.0             # s
    replan_period: float = 1.0       # s of a chosen candidate executed before replanning
    rollout_dt: float = 0.04         # s, rollout step
    cost_stride: int = 5             # clearance checked every cost_stride rollout steps
    sigma_position: float = 0.15     # m, target perturbation (1 sigma per axis)
    sigma_velocity: float = 0.03     # m/s
    w_track: float = 10.0            # per m^2 of mean squared tracking error
    w_collision: float = 1000.0      # once per candidate whose robot or bag leaves the union
    w_clearance: float = 1000.0      # per m^2 of mean squared intrusion into the margin
    clearance_margin: float = 0.05   # m
    w_effort: float = 0.1            # per N^2 of mean squared force
    w_relvel: float = 10.0           # per (m/s)^2 of mean squared bag-robot relative speed
    robot_half_size: float = 0.16    # m, half the robot's envelope (its corners are checked)
    seed: int = 0
    # attitude-aware mode (module docstring): attitude candidates, time scaling, attitude cost
    attitude: bool = False
    attitude_share: float = 0.5      # share of candidates with a recovery attitude reference
    torque_margin: float = 0.7       # recovery feed-forward within this share of torque limits
    time_scale_min: float = 0.0      # slowest translation progress of a candidate (0: pause)
    max_delay: float = 8.0           # s the segment may be delayed in all
    w_attitude: float = 20.0         # per rad^2 of mean squared attitude error to the nominal
    w_momentum: float = 200.0        # per (N m s)^2 of the pair's angular momentum at the end
    w_delay: float = 0.5             # per s of translation delay over the horizon
    max_deviation: float = 0.3       # m from the (time-scaled) nominal; beyond: w_collision
    min_gain: float = 0.1            # leave the nominal candidate only for this share less cost
    hold_about_centre: bool = False  # the end-of-segment hold lets the pair turn about its centre

    def validate(self) -> "MpcConfig":
        """Raise ValueError (one line) for a value the MPC cannot run with."""
        if int(self.samples) != self.samples or self.samples <= 0:
            raise ValueError(f"samples must be a positive integer, got {self.samples!r}")
        for name in ("horizon", "replan_period", "rollout_dt"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number of seconds, got {v!r}")
        if self.replan_period > self.horizon:
            raise ValueError(f"replan_period ({self.replan_period}) must not exceed horizon "
                             f"({self.horizon})")
        if self.rollout_dt > self.horizon / 2:
            raise ValueError(f"rollout_dt ({self.rollout_dt}) must be at most half the horizon")
        if int(self.cost_stride) != self.cost_stride or self.cost_stride <= 0:
            raise ValueError(f"cost_stride must be a positive integer, got {self.cost_stride!r}")
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name.startswith(("w_", "sigma_")) or f.name in ("clearance_margin",
                                                                 "robot_half_size"):
                if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                    raise ValueError(f"{f.name} must be a finite number >= 0, got {v!r}")
        for name, lo, hi in (("attitude_share", 0.0, 1.0), ("torque_margin", 1e-3, 1.0),
                             ("max_deviation", 0.0, 10.0), ("min_gain", 0.0, 1.0),
                             ("time_scale_min", 0.0, 1.0), ("max_delay", 0.0, 60.0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"{name} must be a number in [{lo:g}, {hi:g}], got {v!r}")
        self.samples, self.cost_stride = int(self.samples), int(self.cost_stride)
        self.attitude, self.hold_about_centre = bool(self.attitude), bool(self.hold_about_centre)
        return self

    @classmethod
    def from_params(cls, params: dict) -> "MpcConfig":
        """From a parameter dict (unknown keys ignored), validated."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in params.items() if k in names}).validate()


@dataclass
class Decision:
    """One replan: what was considered and what was chosen."""

    time: float
    targets: np.ndarray          # (N, 3) candidate end positions
    costs: np.ndarray            # (N,)
    clearance: np.ndarray        # (N,) smallest robot/bag clearance over the horizon (m)
    best: int
    candidates: np.ndarray       # (N, K, 3) rolled-out robot positions (display)
    chosen: np.ndarray           # (K, 3)
    executed: SampledTrajectory  # chosen candidate, then the rest of the nominal
    attitude_error: np.ndarray | None = None  # (N,) rad at the horizon's end (attitude mode)
    delay: np.ndarray | None = None           # (N,) s of translation delay (attitude mode)
