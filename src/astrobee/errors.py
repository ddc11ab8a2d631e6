"""The core's input error: one place so realism, overrides and scenario raise the same type
without importing each other."""
from __future__ import annotations


class ScenarioError(ValueError):
    """A scenario, override or realism knob that does not exist or cannot be built; the
    message (one line) says which and why."""
