"""One error base for the planning package: `except PlanningError` catches every failure."""
import numpy as np
import pytest

from astrobee_planning import boxes, planner
from astrobee_planning.errors import NoRoute, OutsideSafeSet, PlanError, PlanningError


def test_every_planning_error_is_a_planning_error():
    for cls in (PlanError, NoRoute, OutsideSafeSet):
        assert issubclass(cls, PlanningError)
    assert issubclass(OutsideSafeSet, ValueError)        # still a bad request to old callers
    assert PlanError(planner.PLAN_FAILED, "x").code == planner.PLAN_FAILED


def test_plan_global_failure_is_caught_as_planning_error():
    with pytest.raises(PlanningError) as exc:
        planner.plan_global([100.0, 0.0, 0.0], [0, 0, 0, 1], [10.0, 0.0, 5.0], [0, 0, 0, 1])
    assert exc.value.code == planner.VIOLATES_KEEP_IN


def test_safe_set_errors_are_planning_errors():
    safe = boxes.safe_set()
    with pytest.raises(PlanningError):
        safe.route(np.array([100.0, 0.0, 0.0]), np.array([100.0, 0.0, 0.0]))
