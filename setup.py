"""Maps the project's package roots (docs/design.md layout) onto one distribution.

pyproject.toml holds the metadata; this file only computes the package list, because the
packages live in several top-level folders (src/, and the ament_python package folders).
"""
from setuptools import find_namespace_packages, find_packages, setup

ROOTS = {
    "roszen": "src/roszen",
    "astrobee": "src/astrobee",
    "astrobee_bringup": "src/astrobee_bringup",
    "astrobee_lab": "src/astrobee_lab",
    "astrobee_sim": "astrobee_sim/astrobee_sim",
    "astrobee_planning": "astrobee_planning/astrobee_planning",
    "astrobee_control": "astrobee_control/astrobee_control",
}

packages = []
for name, path in ROOTS.items():
    packages.append(name)
    packages += [f"{name}.{sub}" for sub in find_packages(path)]

# The shipped interface definitions (.msg/.srv + package.xml) are data packages of roszen
# (listed as packages, so setuptools neither warns nor drops them).
packages += [f"roszen.interfaces.{sub}" for sub in find_namespace_packages("src/roszen/interfaces")
             if "__pycache__" not in sub]
package_data = {"": ["package.xml", "*.msg", "*.srv"]}

setup(packages=packages, package_dir=ROOTS, package_data=package_data)
