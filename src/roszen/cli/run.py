"""`run PKG EXE [args]`: find a node executable the way `ros2 run` does and exec it.

Search order: `<prefix>/lib/<pkg>/<exe>` for every prefix of AMENT_PREFIX_PATH (a colcon or
ROS install), then a registry of Python entry points (`{(pkg, exe): "module:function"}` given
by the caller, plus the `roszen.nodes` entry-point group, names spelled `pkg/exe`).
"""
from __future__ import annotations

import importlib.util
import os
import sys
from dataclasses import dataclass
from importlib.metadata import entry_points

from roszen.cli.common import CliError

Registry = dict[tuple[str, str], str]


@dataclass
class Executable:
    """A resolved node executable: a file to exec, or a Python `module:function`."""

    package: str
    name: str
    path: str | None = None
    target: str | None = None

    def argv(self, args: list[str]) -> list[str]:
        """The argv that starts this executable with `args`."""
        if self.path:
            return [self.path, *args]
        module, _, func = self.target.partition(":")
        # Ctrl-C while the node's modules still import: exit 130 quietly, no traceback
        boot = (f"import sys\nsys.argv[0] = {self.name!r}\ntry:\n"
                f"    from {module} import {func or 'main'} as _main\n"
                f"except KeyboardInterrupt:\n    sys.exit(130)\nsys.exit(_main())")
        return [sys.executable, "-c", boot, *args]


def _ament_candidates(package: str, name: str) -> list[str]:
    found = []
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        path = os.path.join(prefix, "lib", package, name)
        if os.path.isfile(path) and os.access(path, os.X_OK):
            found.append(path)
    return found


def _entry_point_registry() -> Registry:
    reg: Registry = {}
    for ep in entry_points(group="roszen.nodes"):
        pkg, _, exe = ep.name.partition("/")
        if exe:
            reg[(pkg, exe)] = ep.value
    return reg


def packages(registry: Registry | None = None) -> dict[str, set[str]]:
    """Every known package and its executables (ament prefixes and registries)."""
    out: dict[str, set[str]] = {}
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        lib = os.path.join(prefix, "lib")
        if not os.path.isdir(lib):
            continue
        for pkg in os.listdir(lib):
            d = os.path.join(lib, pkg)
            if os.path.isdir(d) and not pkg.startswith("python"):
                for f in os.listdir(d):
                    p = os.path.join(d, f)
                    if os.path.isfile(p) and os.access(p, os.X_OK):
                        out.setdefault(pkg, set()).add(f)
    for (pkg, exe) in {**_entry_point_registry(), **(registry or {})}:
        out.setdefault(pkg, set()).add(exe)
    return out


def resolve(package: str, name: str, registry: Registry | None = None) -> Executable:
    """Find executable `name` of `package`; CliError naming what is missing otherwise."""
    paths = _ament_candidates(package, name)
    if len(paths) > 1 and len(set(map(os.path.realpath, paths))) > 1:
        raise CliError(f"multiple executables found for '{package} {name}': {', '.join(paths)}")
    if paths:
        return Executable(package, name, path=paths[0])
    reg = {**_entry_point_registry(), **(registry or {})}
    target = reg.get((package, name))
    if target is None:
        known = packages(registry)
        if package not in known:
            raise CliError(f"Package '{package}' not found")
        raise CliError(f"No executable found: '{name}' in package '{package}' "
                       f"(has: {', '.join(sorted(known[package]))})")
    module = target.partition(":")[0]
    try:
        spec = importlib.util.find_spec(module)
    except (ImportError, ValueError) as exc:
        spec = None
        reason = str(exc)
    else:
        reason = "no such module"
    if spec is None:
        raise CliError(f"executable '{package} {name}' is not installed: "
                       f"cannot import {module} ({reason})")
    return Executable(package, name, target=target)


def exec_node(package: str, name: str, args: list[str], registry: Registry | None = None) -> None:
    """Replace this process with the node (signals then reach the node directly)."""
    exe = resolve(package, name, registry)
    argv = exe.argv(args)
    sys.stdout.flush()
    sys.stderr.flush()
    os.execv(argv[0], argv)


def main(argv: list[str], prog: str = "roszen") -> int:
    """`run PACKAGE EXECUTABLE [args]`: -h lists what is installed; otherwise exec the node."""
    if not argv or argv[0] in ("-h", "--help"):
        print(f"usage: {prog} run PACKAGE EXECUTABLE [args ...] [--ros-args ...]")
        for pkg, exes in sorted(packages().items()):
            print(f"  {pkg}: {', '.join(sorted(exes))}")
        return 0 if argv else 2
    if len(argv) < 2:
        print(f"{prog} run: missing executable name (usage: {prog} run PACKAGE EXECUTABLE)",
              file=sys.stderr)
        return 2
    exec_node(argv[0], argv[1], argv[2:])
    return 0   # not reached: exec replaced the process
