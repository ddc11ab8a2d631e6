"""Python launcher: starts a launch description's nodes as separate processes and watches them.

Each node runs as `ros2 run PKG EXE` when a ROS 2 install with rmw_zenoh is present, as
`astrobee run PKG EXE` otherwise. Output is prefixed per node (coloured on a tty). Ctrl-C,
SIGTERM or the exit of a required node stops every child: SIGINT, then SIGTERM, then SIGKILL
to its process group, each after a bounded wait; the nodes first, then (after a short grace so
it receives their last messages) the recorder, the router last. The exit status is non-zero
when a node failed.
"""
from __future__ import annotations

import collections
import importlib
import importlib.util
import json
import os
import re
import shlex
import shutil
import signal
import socket
import subprocess
import sys

import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import yaml

COLOURS = ["\033[32m", "\033[36m", "\033[33m", "\033[35m", "\033[34m", "\033[91m", "\033[92m"]
RESET = "\033[0m"
CLEAN_EXIT = {0, -signal.SIGINT, -signal.SIGTERM, 130, 143}
_ERROR_WORDS = re.compile(r"error|cannot|failed|exception|not found|invalid|must be", re.I)
_TS_PREFIX = re.compile(r"^\[(ERROR|FATAL|WARN)\] \[[0-9.]+\] ")


class LaunchError(Exception):
    """A launch that cannot start (unknown description, missing executable, bad argument)."""


@dataclass
class NodeSpec:
    """One process of a launch: a node (package + executable) or a plain command.

    `parameters` holds params files (paths) and dicts of name -> value; `ros_args` extra
    `--ros-args` items (remaps); `required`: its exit stops the launch; `command` replaces
    package/executable with arguments of the `astrobee` command (router, bag record), and
    `ros2_command` with the full argv used instead when running under ROS 2; `argv` starts
    any other program as is. `stop_last` (default for the recorder): stopped after every
    other node, once the launcher's `stop_grace` has passed, so it records their last messages.
    """

    name: str
    package: str = ""
    executable: str = ""
    parameters: list[Any] = field(default_factory=list)
    arguments: list[str] = field(default_factory=list)
    ros_args: list[str] = field(default_factory=list)
    namespace: str = ""
    required: bool = True
    command: list[str] | None = None
    argv: list[str] | None = None
    ros2_command: list[str] | None = None
    env: dict[str, str] = field(default_factory=dict)
    kind: str = "node"          # node | router | recorder | client
    stop_last: bool | None = None   # None: True for kind "recorder"

    @property
    def stops_last(self) -> bool:
        return self.kind == "recorder" if self.stop_last is None else self.stop_last


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


def port_open(port: int, host: str = "127.0.0.1", timeout: float = 0.2) -> bool:
    """True when something accepts TCP connections on host:port."""
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return True
    except OSError:
        return False


def port_override(override: str, port: int) -> str:
    """ZENOH_CONFIG_OVERRIDE `override` with its connect/listen endpoints replaced by the
    router on 127.0.0.1:`port` (an unparsable override is replaced whole)."""
    from roszen.zconfig import ConfigError, parse_override
    try:
        items = parse_override(override)
    except ConfigError:
        items = []
    kept = [f"{k}={v}" for k, v in items
            if k.strip("/") not in ("connect/endpoints", "listen/endpoints")]
    return ";".join([*kept, f'connect/endpoints=["tcp/127.0.0.1:{port}"]'])


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


def _param_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_param_value(v) for v in value) + "]"
    return str(value)


class Launcher:
    """Starts NodeSpecs as child processes, relays their output, stops them all cleanly."""

    def __init__(self, specs: list[NodeSpec], *, use_ros2: bool = False, port: int = 7447,
                 run_dir: Path | None = None, colour: bool | None = None,
                 sigint_timeout: float = 5.0, sigterm_timeout: float = 3.0,
                 stop_grace: float = 0.75, out=None, astrobee_cmd: list[str] | None = None,
                 registry: dict | None = None):
        self.specs = specs
        self.use_ros2 = use_ros2
        self.port = port
        self.run_dir = run_dir
        self.out = out or sys.stdout
        self.colour = self.out.isatty() if colour is None else colour
        self.sigint_timeout = sigint_timeout
        self.sigterm_timeout = sigterm_timeout
        self.stop_grace = stop_grace
        self.astrobee_cmd = astrobee_cmd or [sys.executable, "-m", "astrobee_bringup.cli"]
        self.registry = registry
        self.procs: list[tuple[NodeSpec, subprocess.Popen]] = []
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._reason = ""
        self.failed: list[str] = []
        self._checked = False
        self.cause = ""        # one line: the first node whose exit failed the launch, and why
        self._tails: dict[str, collections.deque] = {}
        self._width = max([len(s.name) for s in specs] + [6])

    # ---- output -------------------------------------------------------------------------
    def log(self, text: str) -> None:
        self._emit("launch", text, -1)

    def _emit(self, name: str, line: str, index: int) -> None:
        tag = f"[{name}]".ljust(self._width + 2)
        if self.colour:
            c = "\033[1m" if index < 0 else COLOURS[index % len(COLOURS)]
            tag = f"{c}{tag}{RESET}"
        with self._lock:
            try:
                self.out.write(f"{tag} {line}\n")
                self.out.flush()
            except (ValueError, OSError):
                pass

    def _relay(self, spec: NodeSpec, proc: subprocess.Popen, index: int) -> None:
        tail = self._tails.setdefault(spec.name, collections.deque(maxlen=30))
        for raw in iter(proc.stdout.readline, b""):
            line = raw.decode("utf-8", "replace").rstrip("\n")
            if line.strip():
                tail.append(line.strip())
            self._emit(spec.name, line, index)
        proc.stdout.close()

    def why(self, spec: NodeSpec, code: int) -> str:
        """One line: how `spec` ended (exit code or signal) and, for an exit code, what it said
        about it (the last of its last 8 lines naming an error, else its last line)."""
        if code < 0:
            try:
                how = f"killed by {signal.Signals(-code).name}"
            except ValueError:
                how = f"killed by signal {-code}"
        else:
            how = f"exited with code {code}"
        t = next((t for t in reversed(self._threads) if t.name == f"relay-{spec.name}"), None)
        if t is not None:
            t.join(timeout=1.0)          # its last lines may still be in the pipe
        lines = list(self._tails.get(spec.name, ()))[-8:]      # what it said last
        # killed by a signal: what it said before is not about that
        said = "" if code < 0 else next((ln for ln in reversed(lines) if _ERROR_WORDS.search(ln)),
                                        lines[-1] if lines else "")
        said = _TS_PREFIX.sub("", said)
        return f"'{spec.name}' {how}" + (f": {said}" if said else "")

    # ---- argv ---------------------------------------------------------------------------
    def argv_for(self, spec: NodeSpec) -> list[str]:
        """The command line that starts `spec` in the current mode."""
        if spec.argv is not None:
            return list(spec.argv)
        if spec.command is not None or spec.ros2_command is not None:
            if self.use_ros2 and spec.ros2_command is not None:
                return list(spec.ros2_command)
            return [*self.astrobee_cmd, *spec.command]
        ros_args: list[str] = []
        for p in spec.parameters:
            if isinstance(p, dict):
                for k, v in p.items():
                    ros_args += ["-p", f"{k}:={_param_value(v)}"]
            else:
                ros_args += ["--params-file", str(p)]
        if spec.namespace:
            ros_args += ["-r", f"__ns:={spec.namespace}"]
        ros_args += spec.ros_args
        tail = [*spec.arguments] + (["--ros-args", *ros_args] if ros_args else [])
        if self.use_ros2:
            return ["ros2", "run", spec.package, spec.executable, *tail]
        return [*self.astrobee_cmd, "run", spec.package, spec.executable, *tail]

    def check(self) -> None:
        """Fail before starting anything if a node's executable cannot be found, or if the
        router's port already serves a graph running nodes of this launch (a second launch on
        one --port would reset the first one's sim and mix both flights)."""
        if self.use_ros2 or self._checked:
            return
        self._checked = True
        if any(s.kind == "router" for s in self.specs) and port_open(self.port):
            ours = {"/" + s.name.strip("/") for s in self.specs if s.kind not in ("router", "recorder")}
            clash = sorted(ours & running_nodes(self.port))
            if clash:
                raise LaunchError(f"the graph on port {self.port} already runs {', '.join(clash)} "
                                  f"(another launch?): give this one its own --port (or ROS_DOMAIN_ID)")
        from roszen.cli.common import CliError
        from roszen.cli.run import resolve
        for spec in self.specs:
            if spec.command is None and spec.argv is None and spec.package:
                try:
                    resolve(spec.package, spec.executable, self.registry)
                except CliError as exc:
                    raise LaunchError(f"cannot start '{spec.name}': {exc}") from None

    # ---- lifecycle ----------------------------------------------------------------------
    def _env(self, spec: NodeSpec) -> dict[str, str]:
        env = dict(os.environ)
        env["PYTHONUNBUFFERED"] = "1"
        if spec.kind == "router":
            # the session override (connect/listen endpoints) is not for the router: its
            # listen endpoint comes from --port
            env.pop("ZENOH_CONFIG_OVERRIDE", None)
        elif not self.use_ros2 and "ZENOH_CONFIG_OVERRIDE" not in spec.env:
            # --port wins: the user's override keeps its other entries, its endpoints are
            # replaced (else the nodes would silently join another router)
            env["ZENOH_CONFIG_OVERRIDE"] = port_override(env.get("ZENOH_CONFIG_OVERRIDE", ""),
                                                         self.port)
        env.update(spec.env)
        return env

    def start(self, spec: NodeSpec) -> subprocess.Popen:
        argv = self.argv_for(spec)
        index = len(self.procs)
        proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, env=self._env(spec),
                                start_new_session=True)
        self.procs.append((spec, proc))
        t = threading.Thread(target=self._relay, args=(spec, proc, index), daemon=True,
                             name=f"relay-{spec.name}")
        t.start()
        self._threads.append(t)
        cmd = shlex.join(argv)
        self.log(f"started '{spec.name}' (pid {proc.pid}): {cmd if len(cmd) < 160 else cmd[:157] + '...'}")
        return proc

    def _wait_router(self, spec: NodeSpec, proc: subprocess.Popen, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if port_open(self.port):
                return
            if proc.poll() is not None:
                raise LaunchError(f"router exited with code {proc.returncode} before listening")
            time.sleep(0.05)
        raise LaunchError(f"router did not listen on port {self.port} within {timeout:.0f} s")

    def stop_all(self) -> None:
        """Stop every live child in three stages: the nodes (reverse start order), then after
        `stop_grace` s the stop-last ones (the recorder: it gets the nodes' final messages and
        closes its bag), the router last. Each stage: SIGINT, SIGTERM, SIGKILL, bounded waits."""
        live = [(s, p) for s, p in reversed(self.procs) if p.poll() is None]
        routers = [(s, p) for s, p in live if s.kind == "router"]
        last = [(s, p) for s, p in live if s.kind != "router" and s.stops_last]
        others = [(s, p) for s, p in live if s.kind != "router" and not s.stops_last]
        self._stop_group(others)
        if last and self.stop_grace > 0 and any(s.kind != "router" and not s.stops_last
                                                for s, _ in self.procs):
            # messages the nodes sent just before exiting may still be on their way
            time.sleep(self.stop_grace)
        self._stop_group(last)
        self._stop_group(routers)
        for t in self._threads:
            t.join(timeout=2.0)

    def _stop_group(self, group) -> None:
        self._signal_wait(group, signal.SIGINT, self.sigint_timeout)
        self._signal_wait(group, signal.SIGTERM, self.sigterm_timeout)
        for s, p in group:
            if p.poll() is None:
                self.log(f"'{s.name}' ignored SIGINT and SIGTERM: SIGKILL")
                self.failed.append(s.name)
                self.cause = self.cause or f"'{s.name}' ignored SIGINT and SIGTERM: killed"
                _killpg(p, signal.SIGKILL)
                p.wait()

    def _signal_wait(self, group, sig, timeout) -> None:
        pending = [(s, p) for s, p in group if p.poll() is None]
        for s, p in pending:
            _killpg(p, sig)
        deadline = time.monotonic() + timeout
        while pending and time.monotonic() < deadline:
            pending = [(s, p) for s, p in pending if p.poll() is None]
            time.sleep(0.05)

    def request_stop(self, reason: str) -> None:
        if not self._stop.is_set():
            self._reason = reason
            self._stop.set()

    def run(self) -> int:
        """Start everything, watch until a signal or a required exit, stop all; exit status."""
        self.check()
        old = {}
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                old[sig] = signal.signal(sig, lambda n, f: self.request_stop(
                    f"received {signal.Signals(n).name}"))
        status = 0
        try:
            for spec in self.specs:
                if self._stop.is_set():
                    break
                if spec.kind == "router" and port_open(self.port):
                    self.log(f"a router already listens on port {self.port}: not starting one")
                    continue
                proc = self.start(spec)
                if spec.kind == "router":
                    self._wait_router(spec, proc, 10.0)
            while not self._stop.wait(0.05):
                for spec, proc in self.procs:
                    code = proc.poll()
                    if code is None or getattr(proc, "_reported", False):
                        continue
                    proc._reported = True
                    ok = code == 0
                    self.log(f"'{spec.name}' exited with code {code}")
                    if not ok:
                        self.failed.append(spec.name)
                        if not self.cause and (spec.required or spec.kind == "client"):
                            self.cause = self.why(spec, code)
                    if spec.required:
                        self.request_stop(f"required node '{spec.name}' exited")
                if all(p.poll() is not None for _, p in self.procs):
                    self.request_stop("every process exited")
            self.log(f"shutting down ({self._reason})")
        except LaunchError as exc:
            self.log(f"error: {exc}")
            status = 1
        finally:
            self.stop_all()
            for sig, handler in old.items():
                signal.signal(sig, handler)
        for spec, proc in self.procs:
            if not getattr(proc, "_reported", False):
                proc._reported = True
                if proc.returncode not in CLEAN_EXIT and spec.name not in self.failed:
                    self.failed.append(spec.name)
                self.log(f"'{spec.name}' stopped (code {proc.returncode})")
        if self.failed:
            self.log(f"failed: {', '.join(dict.fromkeys(self.failed))}")
            if not self.cause:
                spec, proc = next((s, p) for s, p in self.procs if s.name == self.failed[0])
                self.cause = self.why(spec, proc.returncode)
            self.log(f"error: {self.cause}")
            status = 1
        return status


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


def _killpg(proc: subprocess.Popen, sig: int) -> None:
    try:
        os.killpg(proc.pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def running_nodes(port: int, timeout: float = 3.0) -> set[str]:
    """Fully qualified names of the nodes in the graph of the router on `port` (the graph
    cache's first liveliness query answers with every token already there)."""
    import roszen
    from roszen.testing import zenoh_env
    env = zenoh_env(port, domain_id=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0))
    ctx = roszen.Context(env=env)
    try:
        ctx.graph.wait_ready(timeout)
        return {(ns.rstrip("/") + "/" + name) for name, ns in ctx.graph.get_node_names_and_namespaces()}
    finally:
        ctx.shutdown()


def launch(name: str, arguments: dict[str, str], *, port: int = 7447, run_dir: Path | None = None,
           use_ros2: bool | None = None, registry: dict | None = None,
           sigint_timeout: float = 5.0, sigterm_timeout: float = 3.0,
           stop_grace: float = 0.75) -> int:
    """Build launch description `name` with `arguments` and run it; the exit status."""
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


__all__ = ["NodeSpec", "LaunchContext", "Launcher", "LaunchError", "launch", "ros2_available",
           "write_params_file", "flatten_params", "load_description", "list_descriptions"]
