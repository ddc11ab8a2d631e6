"""Python launcher: loads a launch description, checks its arguments and runs its nodes.

Each node runs as `ros2 run PKG EXE` when a ROS 2 install with rmw_zenoh is present, as
`astrobee run PKG EXE` otherwise; the process group (astrobee_bringup.process_group) starts,
watches and stops them. A failed launch's one-line cause goes into the run's summary.json.
"""
from __future__ import annotations

import importlib
import importlib.util
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import yaml

from astrobee_bringup.process_group import Launcher, LaunchError, NodeSpec


@dataclass
class LaunchContext:
    """What a launch description gets: launch arguments, the config dir and the run dir."""

    arguments: dict[str, str]
    config_dir: Path
    run_dir: Path
    use_ros2: bool
    port: int

    def arg(self, name: str, default: str = "") -> str:
        return self.arguments.get(name, default)

    def flag(self, name: str, default: bool = False) -> bool:
        value = self.arguments.get(name)
        if value is None:
            return default
        return value.lower() in ("1", "true", "yes", "on")


def ros2_available() -> bool:
    """A ROS 2 install with rmw_zenoh selected: `ros2` on PATH and RMW_IMPLEMENTATION set."""
    return (shutil.which("ros2") is not None
            and os.environ.get("RMW_IMPLEMENTATION") == "rmw_zenoh_cpp")


def find_config_dir() -> Path:
    """config/ of the project (ASTROBEE_CONFIG_DIR overrides)."""
    from astrobee.config import config_dir
    return config_dir()


def load_description(name: str) -> Callable[[LaunchContext], list[NodeSpec]]:
    """The `generate_nodes` function of launch description `name` (module or .py path)."""
    module = load_module(name)
    fn = getattr(module, "generate_nodes", None)
    if fn is None:
        raise LaunchError(f"launch description '{name}' has no generate_nodes(ctx)")
    return fn


def declared_arguments(name: str) -> dict[str, tuple[str, str]]:
    """The launch arguments description `name` declares: its module-level
    `ARGUMENTS = {name: (default, description)}` (empty when it declares none)."""
    declared = getattr(load_module(name), "ARGUMENTS", None) or {}
    return {k: (str(v[0]), str(v[1])) if isinstance(v, (tuple, list)) else ("", str(v))
            for k, v in declared.items()}


def format_arguments(name: str) -> str:
    """`--show-args` text, laid out as `ros2 launch --show-args` does."""
    declared = declared_arguments(name)
    if not declared:
        return f"launch description '{name}' declares no arguments\n"
    lines = ["Arguments (pass arguments as '<name>:=<value>'):", ""]
    key, default, what = RUNTIME_ARGUMENT          # the launcher's own, for every description
    declared = {**declared, key: (default, what)}
    for key, (default, what) in declared.items():
        lines += [f"    '{key}':", f"        {what}",
                  f"        (default: '{default}')" if default else "        (no default)", ""]
    return "\n".join(lines)


def load_module(name: str):
    """The module of launch description `name` (a module of astrobee_bringup.launch or a .py path)."""
    if name.endswith(".py") and os.path.isfile(name):
        spec = importlib.util.spec_from_file_location(Path(name).stem, name)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    else:
        try:
            module = importlib.import_module(f"astrobee_bringup.launch.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"astrobee_bringup.launch.{name}":
                raise
            raise LaunchError(f"no launch description '{name}' "
                              f"(known: {', '.join(list_descriptions()) or 'none'})") from None
    return module


def list_descriptions() -> list[str]:
    """Names of the launch descriptions shipped in astrobee_bringup/launch/."""
    d = Path(__file__).resolve().parent / "launch"
    return sorted(p.stem for p in d.glob("*.py") if not p.stem.startswith("_"))


def flatten_params(tree: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested config dict -> ROS parameter names joined with dots."""
    out: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.update(flatten_params(value, name + "."))
        else:
            out[name] = value
    return out


def write_params_file(path: Path, node_name: str, params: dict[str, Any]) -> Path:
    """A ROS 2 params file `{node: {ros__parameters: ...}}` for `params`."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as f:
        yaml.safe_dump({node_name: {"ros__parameters": params}}, f, sort_keys=False)
    return path


def _missing_dirs(path: Path) -> list[Path]:
    """`path` and those of its parents that do not exist yet (deepest first)."""
    out = []
    p = Path(path)
    while not p.exists() and p != p.parent:
        out.append(p)
        p = p.parent
    return out


def _remove_created(dirs: list[Path]) -> None:
    """Remove the run folder a rejected launch created, and the parents it created if empty."""
    for i, d in enumerate(dirs):
        if not d.exists():
            continue
        if i == 0:
            shutil.rmtree(d, ignore_errors=True)
        else:
            try:
                d.rmdir()
            except OSError:
                break


def record_cause(run_dir: Path, cause: str) -> None:
    """Put the launcher's one-line cause of failure into run_dir/summary.json.

    The mission only sees that it was stopped ("interrupted"); the launcher knows which process
    died and why. Legs the stop interrupted get the cause as their reason; with no summary (the
    mission never wrote one) a minimal failed one is written."""
    from astrobee_bringup.summary import write_json
    path = run_dir / "summary.json"
    try:
        data = json.loads(path.read_text()) if path.exists() else \
            {"success": False, "status": "failed", "legs": []}
    except (OSError, ValueError):
        return
    data["cause"] = cause
    if data.get("status") == "interrupted":
        data["status"] = "failed"
    for leg in data.get("legs", []):
        if str(leg.get("reason", "")).startswith("interrupted"):
            leg["reason"] = f"stopped: {cause}"
    if len(data.get("legs", [])) == 1 and str(data.get("reason", "")).startswith("interrupted"):
        data["reason"] = data["legs"][0]["reason"]
    write_json(path, data)


RUNTIME_ARGUMENT = ("runtime", "roszen", "roszen (rmw_zenoh's wire, the default) | rclpy (real "
                    "rclpy, any RMW: make install-rclpy or a sourced ROS 2 Jazzy)")


def select_runtime(arguments: dict[str, str]) -> str:
    """The launcher's own `runtime:=` argument (taken out of `arguments`): roszen or rclpy. For
    rclpy every node is started with ASTROBEE_RUNTIME=rclpy (roszen.runtime)."""
    runtime = arguments.pop(RUNTIME_ARGUMENT[0], "") or os.environ.get("ASTROBEE_RUNTIME") or "roszen"
    if runtime not in ("roszen", "rclpy"):
        raise LaunchError(f"runtime:={runtime}: expected roszen | rclpy")
    if runtime == "rclpy" and not _rclpy_importable():
        raise LaunchError("runtime:=rclpy: rclpy is not importable here (make install-rclpy, "
                          "then .venv-rclpy/bin/astrobee; or source a ROS 2 Jazzy install)")
    return runtime


def _rclpy_importable() -> bool:
    """Real rclpy is importable (rclpy.node: a folder named rclpy on the path is no rclpy)."""
    try:
        return importlib.util.find_spec("rclpy.node") is not None
    except ImportError:
        return False


def rclpy_specs(specs: list[NodeSpec]) -> list[NodeSpec]:
    """The launch on real rclpy: no zenoh router; the recorder is roszen's on rclpy
    (roszen.rclpy_backend.record, the same bag options)."""
    from dataclasses import replace
    out = []
    for spec in specs:
        if spec.kind == "router":
            continue
        if spec.kind == "recorder" and spec.command and spec.command[:2] == ["bag", "record"]:
            spec = replace(spec, argv=[sys.executable, "-m", "roszen.rclpy_backend.record",
                                       *spec.command[2:]])
        out.append(spec)
    return out


def launch(name: str, arguments: dict[str, str], *, port: int = 7447, run_dir: Path | None = None,
           use_ros2: bool | None = None, registry: dict | None = None,
           sigint_timeout: float = 5.0, sigterm_timeout: float = 3.0,
           stop_grace: float = 0.75) -> int:
    """Build launch description `name` with `arguments` and run it; the exit status."""
    arguments = dict(arguments)
    runtime = select_runtime(arguments)
    if runtime == "rclpy":
        os.environ["ASTROBEE_RUNTIME"] = "rclpy"      # inherited by every node started
        use_ros2 = False                              # `astrobee run`: this interpreter's rclpy
    else:
        os.environ.pop("ASTROBEE_RUNTIME", None)      # the argument over the environment
    use_ros2 = ros2_available() if use_ros2 is None else use_ros2
    if run_dir is None:
        run_dir = Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    ctx = LaunchContext(arguments=arguments, config_dir=find_config_dir(), run_dir=run_dir,
                        use_ros2=use_ros2, port=port)
    generate = load_description(name)
    declared = declared_arguments(name)
    unknown = [k for k in arguments if declared and k not in declared]
    if unknown:
        raise LaunchError(f"unknown launch argument{'s' if len(unknown) > 1 else ''} "
                          f"{', '.join(unknown)} (`astrobee launch {name} --show-args` lists them)")
    created = _missing_dirs(run_dir)
    try:
        specs = generate(ctx)
        if runtime == "rclpy":
            specs = rclpy_specs(specs)
        launcher = Launcher(specs, use_ros2=use_ros2, port=port, run_dir=run_dir,
                            registry=registry, sigint_timeout=sigint_timeout,
                            sigterm_timeout=sigterm_timeout, stop_grace=stop_grace)
        launcher.check()
    except BaseException:
        _remove_created(created)      # a rejected launch leaves no (half-)empty run folder
        raise
    status = launcher.run()
    if launcher.cause and run_dir.is_dir():
        record_cause(run_dir, launcher.cause)
    # optional `post_run(ctx, status)` of the description: runs once every process has stopped
    # (the bag is closed), e.g. the mission's plots read back from the recorded bag
    post_run = getattr(sys.modules.get(generate.__module__), "post_run", None)
    if post_run is not None:
        try:
            post_run(ctx, status)
        except Exception as exc:  # noqa: BLE001 - a failed report must not hide the status
            launcher.log(f"post-run step failed: {exc}")
    return status


__all__ = ["LaunchContext", "launch", "ros2_available", "write_params_file", "flatten_params",
           "load_description", "list_descriptions"]
