"""Fixtures for the command-line tests: the installed `astrobee` command, free ports, and
child processes that are always killed (process groups) at the end of a test."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from roszen.testing import free_port, pid_alive

ROOT = Path(__file__).resolve().parents[2]
ASTROBEE = str(Path(sys.executable).parent / "astrobee")
HERE = Path(__file__).resolve().parent


class Proc:
    """A child process whose output lines are collected by a thread."""

    def __init__(self, argv, env=None, cwd=None):
        self.argv = argv
        self.popen = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      stdin=subprocess.DEVNULL, env=env, cwd=cwd,
                                      start_new_session=True)
        self.lines: list[str] = []
        self.times: list[float] = []       # time.monotonic() at which each stdout line arrived
        self.err: list[str] = []
        self._cv = threading.Condition()
        self._t = [threading.Thread(target=self._read, args=(self.popen.stdout, self.lines),
                                    daemon=True),
                   threading.Thread(target=self._read, args=(self.popen.stderr, self.err),
                                    daemon=True)]
        for t in self._t:
            t.start()

    def _read(self, stream, sink):
        for raw in iter(stream.readline, b""):
            now = time.monotonic()
            with self._cv:
                if sink is self.lines:
                    self.times.append(now)
                sink.append(raw.decode("utf-8", "replace").rstrip("\n"))
                self._cv.notify_all()
        with self._cv:
            self._cv.notify_all()

    def wait_line(self, pred, timeout=15.0, stream="out"):
        """First output line for which pred(line) is true, or AssertionError after timeout."""
        sink = self.lines if stream == "out" else self.err
        if isinstance(pred, str):
            text = pred
            pred = lambda line: text in line  # noqa: E731
        deadline = time.monotonic() + timeout
        with self._cv:
            seen = 0
            while True:
                for line in sink[seen:]:
                    if pred(line):
                        return line
                seen = len(sink)
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"timeout waiting for output of {self.argv[:4]}; "
                                         f"stdout={self.lines[-20:]} stderr={self.err[-20:]}")
                self._cv.wait(min(left, 0.1))

    def wait(self, timeout=20.0) -> int:
        rc = self.popen.wait(timeout=timeout)
        for t in self._t:
            t.join(timeout=2)
        return rc

    def signal(self, sig):
        self.popen.send_signal(sig)

    def kill(self):
        if self.popen.poll() is None:
            try:
                os.killpg(self.popen.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.popen.wait(timeout=5)


@pytest.fixture
def procs():
    """Start processes with procs(argv, env=...); all are killed at the end of the test."""
    started: list[Proc] = []

    def start(argv, env=None, cwd=None) -> Proc:
        p = Proc(argv, env=env, cwd=cwd)
        started.append(p)
        return p

    yield start
    for p in started:
        p.kill()


@pytest.fixture
def port():
    return free_port()


def graph_env(port: int) -> dict:
    """Environment that makes every roszen process use the router on `port`."""
    from roszen.testing import zenoh_env
    env = zenoh_env(port)
    env.pop("RMW_IMPLEMENTATION", None)
    env.pop("AMENT_PREFIX_PATH", None)
    return env


@pytest.fixture
def router():
    """A roszen router on a free port (killed at the end); yields the port."""
    from roszen import testing
    with testing.router() as port:
        yield port


@pytest.fixture
def env(router):
    return graph_env(router)
