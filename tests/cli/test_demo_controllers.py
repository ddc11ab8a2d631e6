"""The demo's legs and per-robot controllers (cargo_transport.generate_nodes, no processes)."""
import pytest

from astrobee.scenario import Scenario
from astrobee_bringup.launch import cargo_transport
from astrobee_bringup.launcher import LaunchContext, find_config_dir
from astrobee_bringup.process_group import LaunchError


def nodes(tmp_path, **args):
    ctx = LaunchContext(dict(args), find_config_dir(), tmp_path, False, 7447)
    return {s.name: s for s in cargo_transport.generate_nodes(ctx)}


def test_demo_flies_the_fem_bag_with_pd_then_pair_gov_with_the_same_bump(tmp_path):
    legs = [Scenario.load(n) for n in cargo_transport.DEMO_LEGS]
    carrying = [s for s in legs if s.bag is not None]
    assert len(carrying) == 2 and all(s.bag.model == "fem" and s.bag.solver == "fast" for s in carrying)
    # the same bump drawn from the same seed (the launch's, kept across the sim's resets)
    assert carrying[0].realism.disturbances == carrying[1].realism.disturbances
    assert carrying[0].realism.disturbances[0].target == "bag"
    assert list(cargo_transport.DEMO_COMPARE) == [s.name for s in carrying]
    specs = nodes(tmp_path, demo="true")
    # the default robot's PD flies the first two legs, queen's pair_gov (its own namespace) the third
    assert "pd_controller_node" in specs and "queen/pair_gov_controller_node" in specs
    assert specs["queen/pair_gov_controller_node"].namespace == "queen"
    mission = specs["mission"].command
    assert [mission[i + 1] for i, a in enumerate(mission) if a == "--scenario"] == list(cargo_transport.DEMO_LEGS)
    # the PD leg may fail (that is what the demo shows): the pair_gov leg is flown all the same
    assert "--keep-going" in mission
    assert "--keep-going" not in nodes(tmp_path, scenario="node2_to_jem")["mission"].command


def test_controller_argument_applies_to_every_robot(tmp_path):
    specs = nodes(tmp_path, demo="true", controller="pd")
    assert "queen/pd_controller_node" in specs and not any("mpc" in n for n in specs)
    assert "mpc_controller_node" in nodes(tmp_path, scenario="node2_to_jem", controller="mpc")
    assert "queen/mpc_controller_node" in nodes(tmp_path, scenario="node2_to_jem_fem_bag_mpc")
    with pytest.raises(LaunchError, match="controller must be"):
        nodes(tmp_path, scenario="node2_to_jem", controller="lqr")
