"""ament_python packaging of astrobee_control: `colcon build` installs its nodes to lib/astrobee_control/ for `ros2 run`.

The project's own install (pyproject.toml at the repository root) does not use this file.
"""
from setuptools import find_packages, setup

package_name = "astrobee_control"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "tests"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="astrobee-cargo",
    maintainer_email="astrobee-cargo@example.org",
    description="Astrobee cargo-transport controllers (PD tracking, sampling MPC)",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            'pd_controller_node = astrobee_control.pd_controller_node:main',
            'mpc_controller_node = astrobee_control.mpc_controller_node:main',
            'safety_filter_node = astrobee_control.safety_filter_node:main',
            'controller_node = astrobee_control.controller_node:generic_main',
        ],
        # the controller registry (astrobee_control.registry), as pyproject.toml declares it
        # (tests/control/test_controller_registry.py checks they agree)
        "astrobee.controllers": [
            "pd = astrobee_control.tracking:CONTROLLER",
            "mpc = astrobee_control.mpc:CONTROLLER",
            "pair = astrobee_control.pair_law:CONTROLLER",
            "wmpc = astrobee_control.wrench_mpc:CONTROLLER",
            "pair_gov = astrobee_control.pair_governor:CONTROLLER",
            "pd_seed = astrobee_control.seed_pd:CONTROLLER",
        ],
    },
)
