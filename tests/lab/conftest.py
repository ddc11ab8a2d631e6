"""Shared scenarios of the in-process lab tests: short hops inside Node 2 (a few seconds)."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from astrobee.scenario import Scenario

FACING_MINUS_Y = [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]


def hop(bag: dict | None = None, goal_y: float = -0.9, **extra) -> Scenario:
    """A 1.5 m hop along -y in Node 2, with the bag given (None: no bag)."""
    return Scenario.from_dict({
        "description": "short hop in Node 2 (lab tests)", "flight_mode": "nominal",
        "robots": [{"name": "", "position": [10.95, 0.6, 4.84], "orientation": FACING_MINUS_Y}],
        "bag": bag,
        "goal": {"position": [10.95, goal_y, 4.84], "orientation": FACING_MINUS_Y}, **extra},
        "hop")


@pytest.fixture
def make_hop():
    """The hop() factory: make_hop(bag=None, goal_y=-0.9)."""
    return hop


@pytest.fixture
def rigid_hop() -> Scenario:
    return hop({"model": "rigid", "variant": "front", "mass": 10.0})


@pytest.fixture
def study_script():
    """studies/<name>.py loaded as a module (the studies folder holds scripts, not a package)."""
    def load(name: str):
        path = Path(__file__).resolve().parents[2] / "studies" / f"{name}.py"
        spec = importlib.util.spec_from_file_location(name, path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod
    return load
