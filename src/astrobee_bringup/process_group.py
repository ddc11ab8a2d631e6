"""Process group of a launch: starts NodeSpecs as child processes, relays their output and
stops them all cleanly.

Output is prefixed per node (coloured on a tty). Ctrl-C, SIGTERM or the exit of a required node
stops every child: SIGINT, then SIGTERM, then SIGKILL to its process group, each after a bounded
wait; the nodes first, then (after a short grace so it receives their last messages) the
recorder, the router last. The exit status is non-zero when a node failed.
"""
from __future__ import annotations

import collections
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

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
            clash = sorted(running_nodes(self.port, ours))
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
        """Stop every live child in three stages: the nodes one at a time in reverse start order
        (a client is gone before the node it talks to is signalled, so no controller sees the
        simulator leave and reports a lost peer), then after `stop_grace` s the stop-last ones
        (the recorder: it gets the nodes' final messages and closes its bag), the router last.
        Each node and stage: SIGINT, SIGTERM, SIGKILL, bounded waits."""
        live = [(s, p) for s, p in reversed(self.procs) if p.poll() is None]
        routers = [(s, p) for s, p in live if s.kind == "router"]
        last = [(s, p) for s, p in live if s.kind != "router" and s.stops_last]
        others = [(s, p) for s, p in live if s.kind != "router" and not s.stops_last]
        for one in others:
            self._stop_group([one])
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


def _killpg(proc: subprocess.Popen, sig: int) -> None:
    try:
        os.killpg(proc.pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def running_nodes(port: int, names: set[str], timeout: float = 3.0, settle: float = 2.0) -> set[str]:
    """Which of the fully qualified node `names` the graph of the router on `port` runs. The
    graph cache's first liveliness query answers with every token already there (bounded by
    `timeout`); when none of `names` is in it, tokens still on their way get `settle` s more
    (a loaded machine; paid only when a router already listens on the port)."""
    import roszen
    from roszen.testing import zenoh_env
    env = zenoh_env(port, domain_id=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0))
    ctx = roszen.Context(env=env)

    def seen() -> set[str]:
        return names & {(ns.rstrip("/") + "/" + name)
                        for name, ns in ctx.graph.get_node_names_and_namespaces()}
    try:
        ctx.graph.wait_ready(timeout)
        if not seen():
            ctx.graph.wait_for(lambda: bool(seen()), settle)
        return seen()
    finally:
        ctx.shutdown()
