"""astrobee.overrides: one parser of the scenario override keys, whichever source gives them."""
from __future__ import annotations

import subprocess
import sys

import pytest

from astrobee.overrides import OVERRIDE_KEYS, Overrides, parse_overrides
from astrobee.scenario import Scenario, ScenarioError


def test_the_three_sources_give_the_same_overrides():
    launch = parse_overrides({"bag_model": "fem", "bag_mass": "12.5", "bag_resolution": "200",
                              "robots": "honey, bumble", "realism": "harsh", "scenario": "x"},
                             source="launch")
    params = parse_overrides({"bag_model": "fem", "bag_mass": 12.5, "bag_resolution": 200,
                              "robots": "honey,bumble", "realism": "harsh", "fem_solver": ""},
                             source="parameters")
    study = parse_overrides({"bag_model": "fem", "bag_mass": 12.5, "bag_resolution": 200,
                             "robots": ["honey", "bumble"], "realism": "harsh"}, source="study")
    assert launch == params == study == Overrides(
        bag_model="fem", bag_resolution=200, bag_mass=12.5, robots=("honey", "bumble"),
        realism="harsh")
    assert launch.as_parameters()["robots"] == "honey,bumble"
    # not given: '' / None / 0 (the parameters' defaults)
    assert parse_overrides({"bag_mass": 0.0, "bag_resolution": 0, "bag_model": ""},
                           source="parameters") == Overrides()


@pytest.mark.parametrize("values, says", [
    ({"bag_mass": "-3"}, "bag_mass must be 0.05..100 kg, got '-3'"),
    ({"bag_mass": "heavy"}, "bag_mass must be a number"),
    ({"bag_resolution": "1.5"}, "bag_resolution must be an integer"),
    ({"bag_resolution": 10**7}, "bag_resolution must be 27..5000 nodes"),
    ({"bag_model": "jelly"}, "bag_model: unknown value 'jelly'; known: fem,"),
    ({"fem_solver": "slow"}, "fem_solver: unknown value 'slow'"),
    ({"flight_mode": "warp"}, "flight_mode: unknown value 'warp'"),
    ({"robots": "a,a"}, "robots must be 1..4 distinct names"),
    ({"realism": "wild"}, "unknown realism preset 'wild'"),
])
def test_bad_values_are_one_line_naming_the_key(values, says):
    with pytest.raises(ScenarioError) as err:
        parse_overrides(values, source="launch")
    assert says in str(err.value) and "\n" not in str(err.value)


def test_scenario_override_takes_the_type_or_its_keywords():
    ov = parse_overrides({"bag_model": "constraint", "bag_mass": 7.0, "flight_mode": "quiet"})
    a = Scenario.load("node2_to_jem", ov)
    b = Scenario.load("node2_to_jem", bag_model="constraint", bag_mass=7.0, flight_mode="quiet")
    assert a == b and a.bag.model == "constraint" and a.bag.mass == 7.0
    assert Scenario.load("node2_to_jem_bag", bag_model="none").bag is None
    with pytest.raises(TypeError, match="bag_mas"):
        Scenario.load("node2_to_jem", bag_mas=3.0)
    assert set(OVERRIDE_KEYS) >= {"bag_model", "bag_variant", "bag_resolution", "bag_mass",
                                  "fem_solver", "flight_mode", "robots", "realism"}


def test_realism_does_not_import_the_scenario():
    code = "import sys, astrobee.realism; print('astrobee.scenario' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
