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


@pytest.fixture(scope="session")
def safe():
    return boxes.safe_set()
