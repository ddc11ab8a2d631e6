"""The planning package's error types: one base, so `except PlanningError` catches every failure.

PlanError carries an Astrobee Motion result code (planner.py); NoRoute and OutsideSafeSet come
from the safe-box search (OutsideSafeSet is also a ValueError, as a bad request)."""
from __future__ import annotations


class PlanningError(RuntimeError):
    """The planner could not find a trajectory (message says why)."""


class PlanError(PlanningError):
    """A plan request failed; `code` is the Astrobee Motion result code."""

    def __init__(self, code: int, message: str):
        super().__init__(message)
        self.code = code


class NoRoute(PlanningError):
    """No chain of overlapping safe boxes joins the two points."""


class OutsideSafeSet(PlanningError, ValueError):
    """A point lies in no safe box."""


__all__ = ["PlanningError", "PlanError", "NoRoute", "OutsideSafeSet"]
