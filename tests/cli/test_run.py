"""`astrobee run PKG EXE`: found like `ros2 run` (AMENT_PREFIX_PATH, then the registry),
exec'd with its arguments, clear one-line errors otherwise."""
from __future__ import annotations

import os
import signal
import stat

from conftest import ASTROBEE


def _fake_prefix(tmp_path, pkg, exe, body):
    d = tmp_path / "prefix" / "lib" / pkg
    d.mkdir(parents=True)
    f = d / exe
    f.write_text("#!/bin/sh\n" + body)
    f.chmod(f.stat().st_mode | stat.S_IEXEC)
    return tmp_path / "prefix"


def test_run_execs_ament_executable_with_args(procs, tmp_path):
    prefix = _fake_prefix(tmp_path, "demo_pkg", "talker",
                          'echo "pid $$ args: $*"\nexec sleep 30\n')
    env = dict(os.environ, AMENT_PREFIX_PATH=str(prefix))
    p = procs([ASTROBEE, "run", "demo_pkg", "talker", "--ros-args", "-p", "x:=1"], env=env)
    line = p.wait_line("args:")
    assert line.endswith("args: --ros-args -p x:=1")
    # exec: the node is the very process we started, so our signals reach it
    assert int(line.split()[1]) == p.popen.pid
    p.signal(signal.SIGTERM)
    assert p.wait() == -signal.SIGTERM


def test_run_unknown_package_and_executable(procs):
    p = procs([ASTROBEE, "run", "no_such_pkg", "x"])
    assert p.wait() == 1
    assert p.err == ["astrobee run: Package 'no_such_pkg' not found"]
    p = procs([ASTROBEE, "run", "astrobee_sim", "nope"])
    assert p.wait() == 1
    assert len(p.err) == 1 and "No executable found: 'nope'" in p.err[0]
    assert "sim_node" in p.err[0]
