"""Shared fixtures for the planning tests."""
import numpy as np
import pytest

from astrobee import config
from astrobee_planning import boxes


def module_waypoints() -> dict:
    """Module waypoints of config/iss.yaml that lie in the robot's safe set."""
    ss = boxes.safe_set()
    return {k: np.array(v, float) for k, v in config.iss()["waypoints"].items()
            if ss.contains(np.array(v, float))}


def fibonacci_sphere(n: int) -> np.ndarray:
    """n unit vectors spread evenly over the sphere (the golden-angle spiral)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    phi = np.pi * (1 + 5 ** 0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


@pytest.fixture(scope="session")
def safe():
    return boxes.safe_set()
