"""ament_python packaging of astrobee_sim: `colcon build` installs its nodes to lib/astrobee_sim/ for `ros2 run`.

The project's own install (pyproject.toml at the repository root) does not use this file.
"""
from setuptools import find_packages, setup

package_name = "astrobee_sim"

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
    description="Astrobee cargo-transport simulator node (pybullet world: ISS, Astrobee, cargo bag)",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            'sim_node = astrobee_sim.sim_node:main',
        ],
    },
)
