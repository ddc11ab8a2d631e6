"""studies/trace_flight.py: one study flight flown again, a row every so often with pair_gov's
predicted clearance and wanted force beside the commanded wrench; a flight not in the study is
one line and exit 2."""
import numpy as np
import pytest

from astrobee import flight_modes

STUDY = """
name: trace_hop
description: a short hop in Node 2 with the rigid bag
controllers:
  gov: {controller: pair_gov, params: {lever: true, clearance: 0.3, lever_from: bag}}
base:
  scenario:
    name: hop
    description: 0.8 m hop along -y in Node 2
    flight_mode: nominal
    robots: [{name: "", position: [10.95, 0.5, 4.84], orientation: [0, 0, -0.7071067811865476, 0.7071067811865476]}]
    bag: {model: rigid, variant: front, mass: 10.0}
    goal: {position: [10.95, -0.3, 4.84], orientation: [0, 0, -0.7071067811865476, 0.7071067811865476]}
  state_source: truth
seeds: 1
grid:
  controller: [gov]
"""


@pytest.fixture
def study(tmp_path):
    path = tmp_path / "trace_hop.yaml"
    path.write_text(STUDY)
    return str(path)


def test_trace_rows_carry_the_laws_inputs(study_script, study):
    mod = study_script("trace_flight")
    spec = mod.select(study, "gov", 0)
    verdict = {}
    rows = list(mod.trace(spec, 1.0, start=2.0, until=6.0, verdict=verdict))
    assert [r["t"] for r in rows][0] >= 2.0 and rows[-1]["t"] <= 6.0 and 4 <= len(rows) <= 6
    lim = np.asarray(flight_modes.get("nominal").max_force)
    for r in rows:
        assert set(r) <= set(mod.FIELDS)
        assert np.all(np.abs([r["fx"], r["fy"], r["fz"]]) <= lim + 1e-3)
        assert 0.0 < r["predicted_clearance"] < 3.0       # pair_gov with a bag: its columns
    # the hop accelerates along world -y, the body's +x: the loop wants a force there and,
    # unsaturated and upright, the wrench is that force
    assert max(r["want_fx"] for r in rows) > 0.1
    for r in rows:
        assert [r["fx"], r["fy"], r["fz"]] == pytest.approx(
            [r["want_fx"], r["want_fy"], r["want_fz"]], abs=2e-3)
    assert verdict == {} or "success" in verdict       # stopped early: no verdict owed


def test_a_flight_not_in_the_study_is_one_line(study_script, study, capsys):
    mod = study_script("trace_flight")
    assert mod.main([study, "--label", "pd", "--seed", "0"]) == 2
    err = capsys.readouterr().err
    assert "no flight with label 'pd' and seed 0" in err and err.count("\n") == 1
