"""studies/oracle_recovery.py's rows: a plan that is the planned leg itself reads as on the plan
(no offset, no attitude error) with the wrench of each interval; an offset and a turn read back."""

import numpy as np
import pytest

from astrobee import rotations as rot
from astrobee_control import pair_model as pm
from astrobee_lab.oracle import solve as so


def test_recovery_rows_read_the_plan_back(study_script):
    rec = study_script("oracle_recovery")
    params = pm.load("fem_bumped")
    leg = so.plan_leg("node2_to_jem_bag")
    t = np.array([10.0, 10.5, 11.0])
    x = np.array([so.planned_state(leg, params, float(ti)) for ti in t])
    x[2, pm.P_R] += np.array([0.0, 0.3, 0.4])                          # 0.5 m off the plan
    x[2, pm.Q_R] = rot.multiply(x[2, pm.Q_R], rot.from_rotvec(np.array([0.0, 0.0, 0.7])))
    u = np.array([[0.1, 0.0, 0.0, 0.0, 0.0, 0.01], [0.0, 0.2, 0.0, 0.0, 0.02, 0.0]])
    res = so.OracleResult(True, "solved", 1.0, t, x, u)
    rows = rec.recovery_rows(res, leg, params)
    assert [r["t"] for r in rows] == [10.0, 10.5, 11.0]
    assert rows[0]["distance"] == 0.0 and rows[0]["attitude_error"] == 0.0
    assert rows[0]["fx"] == 0.1 and rows[0]["tz"] == 0.01 and rows[1]["ty"] == 0.02
    assert rows[2]["distance"] == pytest.approx(0.5) and rows[2]["attitude_error"] == pytest.approx(0.7)
    assert rows[2]["fy"] == 0.2                       # the last node reads the last interval's
