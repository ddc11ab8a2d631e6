"""ament_python packaging of astrobee_planning: `colcon build` installs its nodes to lib/astrobee_planning/ for `ros2 run`.

The project's own install (pyproject.toml at the repository root) does not use this file.
"""
from setuptools import find_packages, setup

package_name = "astrobee_planning"

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
    description="Astrobee cargo-transport planners (global keep-in planner, local Bezier planner)",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            'planner_node = astrobee_planning.planner_node:main',
        ],
    },
)
