"""Helpers for multi-process tests: free ports, a router subprocess, node processes cleaned up at exit."""
from __future__ import annotations

import atexit
import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from typing import Iterator, Mapping, Optional, Sequence

_procs: list = []


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def pid_alive(pid: int) -> bool:
    """True while a process exists and is not a zombie (for no-leftover checks in tests)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def wait_port(port: int, timeout: float = 10.0, host: str = "127.0.0.1") -> bool:
    """Poll until something accepts TCP connections on port (bounded)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            with socket.create_connection((host, port), timeout=0.2):
                return True
        except OSError:
            time.sleep(0.05)
    return False


def wait_until(cond, timeout: float, period: float = 0.02) -> bool:
    """Poll cond() until it holds or `timeout` seconds pass (bounded); its last value."""
    end = time.monotonic() + timeout
    while not cond() and time.monotonic() < end:
        time.sleep(period)
    return bool(cond())


def spin_until(node, cond, timeout: float, procs: Sequence[subprocess.Popen] = (),
               period: float = 0.05) -> bool:
    """Spin `node` until cond() holds or `timeout` seconds pass; a process of `procs` that
    exited fails the test at once with the end of its stderr."""
    end = time.monotonic() + timeout
    while not cond() and time.monotonic() < end:
        for p in procs:
            assert p.poll() is None, p.stderr.read()[-2000:]
        node.spin_once(timeout_sec=period)
    return bool(cond())


def zenoh_env(port: int, domain_id: Optional[int] = None, base: Optional[Mapping[str, str]] = None) -> dict:
    """Environment for a node process talking to the router on 127.0.0.1:port."""
    env = dict(os.environ if base is None else base)
    env["ZENOH_CONFIG_OVERRIDE"] = (f'connect/endpoints=["tcp/127.0.0.1:{port}"];'
                                    f'listen/endpoints=["tcp/127.0.0.1:0"]')
    env.pop("ZENOH_SESSION_CONFIG_URI", None)
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = str(domain_id)
    env.setdefault("PYTHONUNBUFFERED", "1")
    return env


def spawn(cmd: Sequence[str], env: Optional[Mapping[str, str]] = None, **kw) -> subprocess.Popen:
    """Start a process in its own process group; it is killed at interpreter exit if still alive."""
    kw.setdefault("stdout", subprocess.PIPE)
    kw.setdefault("stderr", subprocess.PIPE)
    p = subprocess.Popen(list(cmd), env=dict(env) if env is not None else None, start_new_session=True,
                         text=True, **kw)
    _procs.append(p)
    return p


def python_cmd(*args: str) -> list:
    """[sys.executable, *args] (the interpreter running the tests)."""
    return [sys.executable, *args]


def stop(p: subprocess.Popen, timeout: float = 3.0) -> Optional[int]:
    """SIGTERM the process group, then SIGKILL after timeout; returns the exit code."""
    if p.poll() is None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(p.pid, signal.SIGTERM)
        try:
            p.wait(timeout)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(p.pid, signal.SIGKILL)
            with contextlib.suppress(subprocess.TimeoutExpired):
                p.wait(timeout)
    for f in (p.stdout, p.stderr, p.stdin):
        if f is not None:
            with contextlib.suppress(Exception):
                f.close()
    if p in _procs:
        _procs.remove(p)
    return p.returncode


def kill9(p: subprocess.Popen) -> None:
    """SIGKILL the process group at once (a crash, as far as the graph can tell)."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(p.pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired):
        p.wait(5)


def _cleanup() -> None:
    for p in list(_procs):
        stop(p, 1.0)


atexit.register(_cleanup)


@contextlib.contextmanager
def router(port: Optional[int] = None, timeout: float = 10.0) -> Iterator[int]:
    """Run `python -m roszen.router` on 127.0.0.1:port in a subprocess; yields the port."""
    port = port or free_port()
    env = dict(os.environ)
    env.pop("ZENOH_ROUTER_CONFIG_URI", None)
    env.pop("ZENOH_CONFIG_OVERRIDE", None)
    p = spawn(python_cmd("-m", "roszen.router", "--listen", f"tcp/127.0.0.1:{port}"), env,
              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        if not wait_port(port, timeout):
            stop(p)
            err = p.stderr.read() if p.stderr and not p.stderr.closed else ""
            raise RuntimeError(f"router on port {port} did not start: {err.strip()}")
        yield port
    finally:
        stop(p)


def _line_queue(p: subprocess.Popen, stream: str):
    """A queue fed by a daemon thread reading p's stream line by line (None at EOF)."""
    import queue
    import threading
    qs = p.__dict__.setdefault("_roszen_line_queues", {})
    q = qs.get(stream)
    if q is None:
        q = queue.SimpleQueue()
        f = getattr(p, stream)

        def pump() -> None:
            try:
                for line in f:
                    q.put(line.rstrip("\n"))
            except (ValueError, OSError):
                pass
            q.put(None)
        threading.Thread(target=pump, daemon=True).start()
        qs[stream] = q
    return q


def read_until(p: subprocess.Popen, needle: str, timeout: float = 10.0, stream: str = "stdout") -> list:
    """Read lines from p's stdout (or stderr) until one contains needle; returns the lines read.

    Raises TimeoutError (with the lines seen) when the bounded wait passes or the process exits.
    """
    import queue
    q = _line_queue(p, stream)
    lines: list = []
    end = time.monotonic() + timeout
    while True:
        rem = end - time.monotonic()
        if rem <= 0:
            raise TimeoutError(f"{needle!r} not seen in {timeout} s; got {lines[-20:]}")
        try:
            line = q.get(timeout=rem)
        except queue.Empty:
            continue
        if line is None:
            q.put(None)
            raise TimeoutError(f"process exited ({p.poll()}) before {needle!r}; got {lines[-20:]}")
        lines.append(line)
        if needle in line:
            return lines


def drain(p: subprocess.Popen, stream: str = "stdout", wait: float = 0.0) -> list:
    """Lines already read from p's stream (waiting up to `wait` s for the first one)."""
    import queue
    q = _line_queue(p, stream)
    out: list = []
    try:
        line = q.get(timeout=wait) if wait > 0 else q.get_nowait()
        while line is not None:
            out.append(line)
            line = q.get_nowait()
        q.put(None)
    except queue.Empty:
        pass
    return out
