"""The demo's legs and per-robot controllers (cargo_transport.generate_nodes, no processes;
the last test builds the controller node in-process on the test router)."""
import shutil

import pytest
import yaml

from astrobee.scenario import Scenario
from astrobee_bringup.launch import cargo_transport
from astrobee_bringup.launcher import LaunchContext, find_config_dir
from astrobee_bringup.process_group import LaunchError


def nodes(tmp_path, **args):
    ctx = LaunchContext(dict(args), find_config_dir(), tmp_path, False, 7447)
    return {s.name: s for s in cargo_transport.generate_nodes(ctx)}


def test_demo_flies_the_fem_bag_with_pd_then_gov_uwm_with_the_same_bump(tmp_path):
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
    # ... with the last leg's controller_params: gov_uwm (studies/unwind_margin_replication.yaml)
    assert params_file(specs["queen/pair_gov_controller_node"]) == {
        **GOV_BAG, "momentum": 1.0, "fit": 0.3, "hold_error": 0.2, "unwind": True,
        "unwind_margin": 0.8}
    assert params_file(specs["pd_controller_node"]) == {}
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


GOV_CLEAR = {"pair_gov": {"lever": True, "clearance": 0.3}}     # studies/lever_clearance.yaml
GOV_BAG = {"lever": True, "clearance": 0.3, "lever_from": "bag"}  # studies/lever_bag.yaml


def params_file(spec) -> dict:
    """The ros__parameters of a controller's params file (its first parameters entry)."""
    (node, body), = yaml.safe_load(spec.parameters[0].read_text()).items()
    return body["ros__parameters"]


def test_controller_params_reach_every_robot_flying_the_law(tmp_path):
    """controller_params:= over config/controllers.yaml: the law's params file carries the
    merged overrides (gov_clear); a law of the file no robot flies (mpc) is checked, then left
    out."""
    given = tmp_path / "gov_clear.yaml"
    given.write_text(yaml.safe_dump({**GOV_CLEAR, "mpc": {"samples": 64}}))
    config = tmp_path / "config"
    config.mkdir()
    (config / "controllers.yaml").write_text(yaml.safe_dump(
        {"pair_gov": {"clearance": 0.1, "momentum": 0.5}, "pd": {"settle_time": 4.0}}))
    ctx = LaunchContext({"scenario": "two_robots_bag", "controller": "pair_gov",
                         "controller_params": str(given)}, config, tmp_path / "run", False, 7447)
    specs = [s for s in cargo_transport.generate_nodes(ctx) if "controller_node" in s.name]
    assert sorted(s.name for s in specs) == ["bumble/pair_gov_controller_node",
                                             "pair_gov_controller_node"]
    assert all(params_file(s) == {"clearance": 0.3, "momentum": 0.5, "lever": True} for s in specs)
    assert sorted(p.name for p in (tmp_path / "run" / "params").iterdir()) == \
        ["pair_gov_controller_node.yaml"]
    # without the argument: config/controllers.yaml's section alone, as before
    ctx = LaunchContext({"scenario": "node2_to_jem"}, config, tmp_path / "run2", False, 7447)
    pd = next(s for s in cargo_transport.generate_nodes(ctx) if s.name == "pd_controller_node")
    assert params_file(pd) == {"settle_time": 4.0}


@pytest.mark.parametrize("site, says", [
    ({"pair_gov": {"clearence": 0.3}}, "pair_gov has no parameter 'clearence' (did you mean "
                                       "'clearance'?)"),
    ({"pair_gov": {"clearance": -1}}, "controller pair_gov: clearance must be a finite number "
                                      ">= 0"),
    ({"pair_gov": {"clearance": "far"}}, "pair_gov parameter 'clearance': expected double"),
    ({"pair_gov": 3}, "pair_gov must map parameter names to values, got 3"),
])
def test_config_controllers_yaml_overrides_are_checked(tmp_path, site, says):
    """config/controllers.yaml's section is checked as merged: a name the law does not have (it
    was passed to the node, which ignored it) and a section that is no mapping (it was a
    TypeError) are one line too."""
    (tmp_path / "controllers.yaml").write_text(yaml.safe_dump(site))
    ctx = LaunchContext({"scenario": "node2_to_jem_fem_bag_pair_gov"}, tmp_path, tmp_path / "run",
                        False, 7447)
    with pytest.raises(LaunchError) as err:
        cargo_transport.generate_nodes(ctx)
    assert says in str(err.value) and "\n" not in str(err.value)
    assert not (tmp_path / "run").exists()


def test_controller_params_reach_the_law_in_the_node(tmp_path, router_env):
    """The controller node built from the launch's own argv (params file, name, namespace)
    flies gov_clear: its law's config has the lever and the clearance weight."""
    from astrobee_bringup.process_group import Launcher
    from astrobee_control.controller_node import ControllerNode
    from astrobee_control import registry
    given = tmp_path / "gov_clear.yaml"
    given.write_text(yaml.safe_dump(GOV_CLEAR))
    specs = nodes(tmp_path, scenario="node2_to_jem_fem_bag_pair_gov",
                  controller_params=str(given))
    spec = specs["queen/pair_gov_controller_node"]
    argv = Launcher([spec], astrobee_cmd=["astrobee"]).argv_for(spec)
    law = registry.get("pair_gov")
    node = ControllerNode(law.make_law, law.node_name, dict(law.params()),
                          ["controller_node"] + argv[argv.index("--ros-args"):])
    try:
        assert node.node.get_parameter("clearance").value == 0.3
        assert node.law.pd.config.lever is True and node.law.pd.config.clearance == 0.3
    finally:
        node.node.destroy_node()


def scenario_file(tmp_path, monkeypatch, name: str, **extra):
    """A copy of config/ whose scenarios/<name>.yaml is node2_to_jem_fem_bag_gov_bag's with
    `extra` over it, made the config dir."""
    config = tmp_path / "config"
    shutil.copytree(find_config_dir(), config)
    data = yaml.safe_load((config / "scenarios" / "node2_to_jem_fem_bag_gov_bag.yaml").read_text())
    (config / "scenarios" / f"{name}.yaml").write_text(yaml.safe_dump({**data, **extra}))
    monkeypatch.setenv("ASTROBEE_CONFIG_DIR", str(config))
    return config


def test_scenario_controller_params_under_the_file_and_not_for_another_law(tmp_path):
    """A scenario's controller_params reach its law, under controller_params:=; with
    controller:= naming another law they are not used."""
    given = tmp_path / "more.yaml"
    given.write_text(yaml.safe_dump({"pair_gov": {"clearance": 0.2}}))
    specs = nodes(tmp_path, scenario="node2_to_jem_fem_bag_gov_bag", controller_params=str(given))
    assert params_file(specs["queen/pair_gov_controller_node"]) == {**GOV_BAG, "clearance": 0.2}
    specs = nodes(tmp_path, scenario="node2_to_jem_fem_bag_gov_bag", controller="pd")
    assert params_file(specs["queen/pd_controller_node"]) == {}


@pytest.mark.parametrize("extra, says", [
    ({"controller_params": {"lever_form": "bag"}},
     "scenario bad: controller_params: pair_gov has no parameter 'lever_form' (did you mean "
     "'lever_from'?)"),
    ({"controller_params": {"lever_from": "robot"}},
     "scenario bad: controller_params: lever_from must be one of grasp, bag, got 'robot'"),
    ({"controller_params": [1, 2]}, "scenario bad: controller_params must map parameter names "
                                    "to values, got [1, 2]"),
])
def test_bad_scenario_controller_params_one_line(tmp_path, monkeypatch, extra, says):
    config = scenario_file(tmp_path, monkeypatch, "bad", **extra)
    ctx = LaunchContext({"scenario": "bad"}, config, tmp_path / "run", False, 7447)
    with pytest.raises(LaunchError) as err:
        cargo_transport.generate_nodes(ctx)
    assert says in str(err.value) and "\n" not in str(err.value)
    assert not (tmp_path / "run").exists()


def test_two_legs_flying_one_law_must_agree_on_its_scenario_params(tmp_path, monkeypatch):
    """One node per robot and law, so one set of parameters: legs that give the same law other
    controller_params are refused (one line) before any process starts."""
    monkeypatch.setattr(cargo_transport, "DEMO_LEGS", ("node2_to_jem_fem_bag_pair_gov",
                                                       "node2_to_jem_fem_bag_gov_bag"))
    with pytest.raises(LaunchError) as err:
        nodes(tmp_path, demo="true")
    assert str(err.value) == ("scenario node2_to_jem_fem_bag_gov_bag: pair_gov flies with other "
                              "controller_params than in node2_to_jem_fem_bag_pair_gov: one set "
                              "of parameters per law")


def test_demo_law_is_the_studys_gov_uwm():
    """The demo's last leg flies the very parameters studies/unwind_margin_replication.yaml
    flew as gov_uwm."""
    from pathlib import Path
    study = yaml.safe_load((Path(__file__).resolve().parents[2] / "studies"
                            / "unwind_margin_replication.yaml").read_text())
    from astrobee import config
    leg = config.scenario(cargo_transport.DEMO_LEGS[-1])
    assert leg["controller"] == study["controllers"]["gov_uwm"]["controller"]
    assert leg["controller_params"] == study["controllers"]["gov_uwm"]["params"]
