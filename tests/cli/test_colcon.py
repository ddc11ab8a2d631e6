"""`colcon build` (colcon from PyPI, no ROS) of the three node packages installs every node
executable in install/<pkg>/lib/<pkg>/, where `ros2 run` looks, and `astrobee run` finds it
there through AMENT_PREFIX_PATH before its own registry."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT

def _registry() -> dict[str, list[str]]:
    """The node executables of the ament packages, from the one registry (entry points)."""
    from importlib.metadata import entry_points
    out: dict[str, list[str]] = {}
    for ep in entry_points(group="roszen.nodes"):
        pkg, _, exe = ep.name.partition("/")
        if (ROOT / pkg / "setup.py").is_file():
            out.setdefault(pkg, []).append(exe)
    return out


EXECUTABLES = _registry()
COLCON = Path(sys.executable).parent / "colcon"


@pytest.mark.slow
@pytest.mark.skipif(not COLCON.exists(), reason="colcon not installed in the venv")
def test_colcon_build_installs_where_ros2_run_looks(tmp_path):
    src = tmp_path / "src"
    for pkg in EXECUTABLES:
        shutil.copytree(ROOT / pkg, src / pkg,
                        ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "build"))
    proc = subprocess.run([str(COLCON), "build", "--base-paths", str(src)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    install = tmp_path / "install"
    for pkg, exes in EXECUTABLES.items():
        assert (install / pkg / "share" / "ament_index" / "resource_index" / "packages"
                / pkg).is_file()
        assert (install / pkg / "share" / pkg / "package.xml").is_file()
        for exe in exes:
            path = install / pkg / "lib" / pkg / exe
            assert path.is_file() and os.access(path, os.X_OK), path
            assert f"{pkg}.{exe}" in path.read_text() or exe in path.read_text()

    # `astrobee run` resolves through AMENT_PREFIX_PATH first, like `ros2 run`
    from roszen.cli.run import resolve
    old = os.environ.get("AMENT_PREFIX_PATH")
    os.environ["AMENT_PREFIX_PATH"] = os.pathsep.join(str(install / p) for p in EXECUTABLES)
    try:
        exe = resolve("astrobee_control", "pd_controller_node")
        assert exe.path == str(install / "astrobee_control" / "lib" / "astrobee_control"
                               / "pd_controller_node")
    finally:
        if old is None:
            del os.environ["AMENT_PREFIX_PATH"]
        else:
            os.environ["AMENT_PREFIX_PATH"] = old


def test_ament_packages_list_the_registry_executables():
    """Each package's setup.py console_scripts are exactly its entries in the registry."""
    import re
    from importlib.metadata import entry_points
    reg = {ep.name: ep.value for ep in entry_points(group="roszen.nodes")}
    assert {"astrobee_sim", "astrobee_planning", "astrobee_control"} <= set(EXECUTABLES)
    for pkg in EXECUTABLES:
        text = (ROOT / pkg / "setup.py").read_text()
        scripts = dict(re.findall(r"'(\w+) = ([\w.]+:\w+)'", text))
        assert scripts == {exe: reg[f"{pkg}/{exe}"] for exe in EXECUTABLES[pkg]}, pkg


def test_package_xml_is_ament_python_format_3():
    import xml.etree.ElementTree as ET
    for pkg in EXECUTABLES:
        root = ET.parse(ROOT / pkg / "package.xml").getroot()
        assert root.get("format") == "3"
        assert root.findtext("name") == pkg
        assert root.find("export").findtext("build_type") == "ament_python"
        assert (ROOT / pkg / "resource" / pkg).is_file()
        cfg = (ROOT / pkg / "setup.cfg").read_text()
        assert f"script_dir=$base/lib/{pkg}" in cfg and f"install_scripts=$base/lib/{pkg}" in cfg
