"""The controller registry (astrobee_control.registry): a third law, installed by this test as a
package of its own (a dist-info with one `astrobee.controllers` entry point on sys.path, found
as an installed package is), appears in the launcher's choices and --show-args, in Flight, in
study specs and as a node executable, with no other file edited."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from astrobee_control import registry

ASTROBEE = str(Path(sys.executable).parent / "astrobee")

LAW_MODULE = '''
from astrobee_control.hold import HoldLaw
from astrobee_control.registry import Controller


def check(params):
    if not params["gain"] > 0:
        raise ValueError(f"gain must be > 0, got {params['gain']!r}")


def make_law(flight_mode, mass, params):
    check(params)
    law = HoldLaw(flight_mode, mass)
    law.name = "third"
    return law


CONTROLLER = Controller("third", make_law, {"gain": 1.0, "seed": 0}, check, "hold, as a test")
'''


@pytest.fixture
def third_law(tmp_path, monkeypatch):
    """A package `third_law` registering the law 'third' (no file of the project edited)."""
    site = tmp_path / "site"
    dist = site / "third_law-0.1.dist-info"
    dist.mkdir(parents=True)
    (site / "third_law.py").write_text(LAW_MODULE)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: third-law\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[astrobee.controllers]\nthird = third_law:CONTROLLER\n")
    monkeypatch.syspath_prepend(str(site))
    registry.refresh()
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site)] + [p for p in [env.get("PYTHONPATH")] if p])
    yield env
    monkeypatch.undo()
    registry.refresh()


def test_the_installed_laws_are_registered():
    assert {"pd", "mpc"} <= set(registry.names()) and registry.names() == tuple(
        sorted(registry.names()))
    pd, mpc = registry.get("pd"), registry.get("mpc")
    assert pd.parameters["settle_time"] == mpc.parameters["settle_time"]
    assert mpc.check_params({"samples": 16})["samples"] == 16
    with pytest.raises(ValueError, match="samples must be a positive integer"):
        mpc.check_params({"samples": 0})
    with pytest.raises(ValueError, match="workers must be a positive integer"):
        mpc.check_params({"workers": 0})
    with pytest.raises(ValueError, match="settle_time must be > 0"):
        pd.check_params({"settle_time": -1})
    with pytest.raises(registry.UnknownController, match="unknown controller 'lqr'; known: "):
        registry.get("lqr")


def test_a_third_law_appears_everywhere(third_law, tmp_path):
    from astrobee import flight_modes
    from astrobee_bringup.launch import cargo_transport
    from astrobee_bringup.launcher import LaunchContext, find_config_dir
    from astrobee_bringup.process_group import Launcher
    from astrobee_lab.flight import make_controller
    from astrobee_lab.study.spec import StudyError, parse_study

    assert "third" in registry.names()
    # the launcher: a choice, run by the generic controller_node under its own node name
    ctx = LaunchContext({"controller": "third", "seed": "3"}, find_config_dir(), tmp_path, False,
                        7447)
    specs = {s.name: s for s in cargo_transport.generate_nodes(ctx)}
    node = specs["third_controller_node"]
    assert (node.executable, node.arguments) == ("controller_node", ["third"])
    assert "__node:=third_controller_node" in node.ros_args
    assert node.parameters[1]["seed"] == 3           # it declares a seed: the run's is given
    Launcher(list(specs.values()), use_ros2=False, port=7447, run_dir=tmp_path).check()
    out = subprocess.run([ASTROBEE, "launch", "cargo_transport", "--show-args"], env=third_law,
                         capture_output=True, text=True, timeout=60)
    lines = out.stdout.splitlines()
    described = lines[lines.index("    'controller':") + 1].split(" for every robot")[0]
    assert out.returncode == 0 and "third" in described.split(" | "), out.stdout
    # Flight's make_controller
    law = make_controller("third", flight_modes.get(None))
    assert law.name == "third"
    with pytest.raises(ValueError, match="gain must be > 0"):
        make_controller("third", flight_modes.get(None), {"gain": -1.0})
    # study specs: the default labels, and the law's own checker
    hop = {"robots": [{"name": "", "position": [10.95, 0.4, 4.84]}],
           "goal": {"position": [10.95, -0.1, 4.84]}}
    study = parse_study({"base": {"scenario": hop}, "grid": {"controller": ["third"]}})
    assert [f.spec["controller"] for f in study.flights] == ["third"]
    with pytest.raises(StudyError, match="gain must be > 0"):
        parse_study({"controllers": {"t": {"controller": "third", "params": {"gain": 0}}},
                     "base": {"scenario": hop}, "grid": {"controller": ["t"]}})
    # the node executable: the generic controller_node runs it (a bad parameter: one line)
    from roszen.testing import free_port, zenoh_env
    env = {**third_law, **zenoh_env(free_port())}
    out = subprocess.run([ASTROBEE, "run", "astrobee_control", "controller_node", "third",
                          "--ros-args", "-p", "gain:=-2.0"], env=env, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 1 and "controller_node: error: gain must be > 0, got -2.0" in \
        out.stderr, out.stderr


def test_the_ament_package_registers_the_same_laws():
    """astrobee_control/setup.py (colcon builds) lists the laws pyproject.toml registers."""
    import re
    import tomllib
    root = Path(__file__).resolve().parents[2]
    project = tomllib.loads((root / "pyproject.toml").read_text())
    declared = project["project"]["entry-points"][registry.GROUP]
    text = (root / "astrobee_control" / "setup.py").read_text()
    block = text[text.index(f'"{registry.GROUP}"'):]
    block = block[:block.index("]")]
    assert dict(re.findall(r'"(\w+) = ([\w.]+:\w+)"', block)) == declared
