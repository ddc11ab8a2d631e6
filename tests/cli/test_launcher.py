"""The launcher from a shell: children prefixed, stopped on signals and on a required node's
death (SIGINT, SIGTERM, SIGKILL escalation), non-zero exit on failure, nothing left running."""
from __future__ import annotations

import io
import re
import signal
import sys
import time

import pytest

from astrobee_bringup.process_group import Launcher, LaunchError, NodeSpec
from conftest import ASTROBEE, HERE, graph_env, pid_alive

FAKE = str(HERE / "launch_files" / "fake_graph.py")
pytestmark = pytest.mark.graph


def _pids(proc) -> dict[str, int]:
    out = {}
    for line in proc.lines:
        m = re.search(r"started '(\w+)' \(pid (\d+)\)", line)
        if m:
            out[m.group(1)] = int(m.group(2))
    return out


def _launch(procs, port, tmp_path, nodes, *extra):
    return procs([ASTROBEE, "launch", FAKE, f"nodes={nodes}".replace("=", ":="),
                  "--port", str(port), "--run-dir", str(tmp_path / "run"),
                  "--sigint-timeout", "2", "--sigterm-timeout", "2", *extra],
                 env=graph_env(port))


def _all_dead(pids, timeout=5.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if not any(pid_alive(p) for p in pids):
            return True
        time.sleep(0.05)
    return [p for p in pids if pid_alive(p)]


def test_required_node_death_stops_everything(procs, port, tmp_path):
    p = _launch(procs, port, tmp_path, "sleep,crash")
    rc = p.wait(timeout=30)
    assert rc != 0
    out = "\n".join(p.lines)
    assert "[crash1]" in out and "crashing now" in out
    assert "'crash1' exited with code 3" in out
    assert "failed: crash1" in out
    pids = _pids(p)
    assert set(pids) == {"router", "sleep0", "crash1"}
    assert _all_dead(pids.values()) is True


def test_optional_node_failure_keeps_running_then_nonzero(procs, port, tmp_path):
    p = _launch(procs, port, tmp_path, "sleep,optional_crash")
    p.wait_line("'optional_crash1' exited with code 3")
    time.sleep(0.3)
    assert p.popen.poll() is None          # a non-required node does not stop the launch
    p.signal(signal.SIGINT)
    assert p.wait(timeout=30) == 1         # ... but the launch reports the failure
    assert _all_dead(_pids(p).values()) is True


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_stops_children_cleanly(procs, port, tmp_path, sig):
    p = _launch(procs, port, tmp_path, "sleep,noint")
    p.wait_line("[noint1]")
    p.wait_line("[sleep0]")
    p.signal(sig)
    rc = p.wait(timeout=30)
    pids = _pids(p)
    assert _all_dead(pids.values()) is True
    assert rc == 0, p.lines[-10:]
    assert f"received {sig.name}" in "\n".join(p.lines)


def test_child_ignoring_sigterm_is_killed_and_reported(procs, port, tmp_path):
    p = _launch(procs, port, tmp_path, "noterm")
    p.wait_line("[noterm0]")
    p.signal(signal.SIGTERM)
    assert p.wait(timeout=30) == 1
    assert "ignored SIGINT and SIGTERM: SIGKILL" in "\n".join(p.lines)
    assert _all_dead(_pids(p).values()) is True


def test_existing_router_is_reused(procs, port, tmp_path):
    router = procs([ASTROBEE, "router", "--port", str(port)], env=graph_env(port))
    router.wait_line("running", stream="err")
    p = _launch(procs, port, tmp_path, "crash")
    assert p.wait(timeout=30) == 1
    assert "already listens" in "\n".join(p.lines)
    assert router.popen.poll() is None     # not ours: left alone


def test_missing_node_module_fails_clearly_before_starting(tmp_path):
    spec = NodeSpec("ghost", "astrobee_control", "ghost_node")
    launcher = Launcher([spec], registry={("astrobee_control", "ghost_node"):
                                          "astrobee_control.ghost_node:main"})
    with pytest.raises(LaunchError, match="cannot import astrobee_control.ghost_node"):
        launcher.run()
    assert launcher.procs == []


def test_unknown_description_and_bad_argument(procs, tmp_path):
    p = procs([ASTROBEE, "launch", "no_such_launch"])
    assert p.wait() == 1
    assert len(p.err) == 1 and "no launch description 'no_such_launch'" in p.err[0]
    p = procs([ASTROBEE, "launch", FAKE, "nodes=sleep"])
    assert p.wait() == 1
    assert len(p.err) == 1 and "name:=value" in p.err[0]


def test_cargo_transport_lists_the_graph(tmp_path):
    from astrobee_bringup.launch import cargo_transport
    from astrobee_bringup.launcher import LaunchContext, find_config_dir
    ctx = LaunchContext({"scenario": "node2_to_jem"}, find_config_dir(), tmp_path, False, 7447)
    specs = cargo_transport.generate_nodes(ctx)
    names = [s.name for s in specs]
    assert names[:5] == ["router", "sim_node", "planner_node", "pd_controller_node", "recorder"]
    assert LaunchContext({"record": "false"}, find_config_dir(), tmp_path, False, 7447) and \
        "recorder" not in [s.name for s in cargo_transport.generate_nodes(
            LaunchContext({"record": "false"}, find_config_dir(), tmp_path, False, 7447))]
    launcher = Launcher(specs, astrobee_cmd=["astrobee"])
    argv = launcher.argv_for(specs[3])
    assert argv[:4] == ["astrobee", "run", "astrobee_control", "pd_controller_node"]
    params = argv[argv.index("--params-file") + 1]
    assert "ros__parameters" in open(params).read()
    ros2 = Launcher(specs, use_ros2=True)
    assert ros2.argv_for(specs[1])[:4] == ["ros2", "run", "astrobee_sim", "sim_node"]
    assert ros2.argv_for(specs[0]) == ["ros2", "run", "rmw_zenoh_cpp", "rmw_zenohd"]
    with pytest.raises(LaunchError, match="unknown scenario"):
        cargo_transport.generate_nodes(LaunchContext({"scenario": "nope"}, find_config_dir(),
                                                     tmp_path, False, 7447))


def test_ros2_mode_uses_ros2_run_when_ros2_and_rmw_zenoh_are_present(procs, port, tmp_path):
    """With `ros2` on PATH and RMW_IMPLEMENTATION=rmw_zenoh_cpp, nodes start via `ros2 run`
    (here a stand-in `ros2` script that reports its arguments)."""
    import os
    import stat
    fake = tmp_path / "bin" / "ros2"
    fake.parent.mkdir()
    fake.write_text(f"""#!/bin/sh
echo "ros2 $*"
if [ "$1 $2 $3" = "run rmw_zenoh_cpp rmw_zenohd" ]; then
  exec {ASTROBEE} router --port {port}
fi
exec sleep 60
""")
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    env = graph_env(port)
    env["PATH"] = f"{fake.parent}{os.pathsep}{env['PATH']}"
    env["RMW_IMPLEMENTATION"] = "rmw_zenoh_cpp"
    p = procs([ASTROBEE, "launch", str(HERE / "launch_files" / "ros2_mode.py"), "--port",
               str(port), "--run-dir", str(tmp_path / "run")], env=env)
    p.wait_line("[router] ros2 run rmw_zenoh_cpp rmw_zenohd")
    line = p.wait_line("[talker] ros2 run")
    assert line.split("] ", 1)[1].strip() == \
        "ros2 run demo_nodes_py talker --ros-args -p x:=1 -p flag:=true -r chatter:=/talk"
    p.signal(signal.SIGINT)
    assert p.wait(timeout=30) == 0
    assert _all_dead(_pids(p).values()) is True


_SAYS = """
import signal, sys, time
def stop(*_):
    time.sleep(float(sys.argv[3]))        # work a node finishes after SIGINT
    open(sys.argv[1], "a").write(sys.argv[2] + " stopped\\n")
    sys.exit(0)
signal.signal(signal.SIGINT, stop)
print("up", flush=True)
while True:
    time.sleep(0.05)
"""


def _says(log, name: str, delay: float, **kw) -> NodeSpec:
    """A node that writes '<name> stopped' to `log` `delay` s after its SIGINT."""
    return NodeSpec(name, required=False,
                    argv=[sys.executable, "-c", _SAYS, str(log), name, str(delay)], **kw)


def _stop_order(specs: list[NodeSpec], log, stop_grace: float) -> list[str]:
    """Launch `specs` with a required node that quits after 1 s; the lines the nodes wrote as
    they were stopped, in order (the log is emptied for the next launch)."""
    quitter = NodeSpec("quitter", required=True,
                       argv=[sys.executable, "-c", "import time; time.sleep(1.0)"])
    out = io.StringIO()
    launcher = Launcher([*specs, quitter], out=out, colour=False, stop_grace=stop_grace)
    assert launcher.run() == 0, out.getvalue()
    assert all(p.poll() is not None for _, p in launcher.procs)
    lines = log.read_text().splitlines()
    log.unlink()
    return lines


def test_recorder_is_stopped_after_the_nodes(tmp_path):
    """Shutdown order: every node has exited (and the grace passed) before the recorder gets
    SIGINT, so what the nodes send last reaches the bag."""
    log = tmp_path / "order.txt"
    recorder = _says(log, "recorder", 0, kind="recorder")
    node = _says(log, "node", 0.3)               # a node finishing its work after SIGINT
    assert _stop_order([recorder, node], log, 0.2) == ["node stopped", "recorder stopped"]
    # the recorder is started first, so it would be stopped last anyway: started after the
    # node with an explicit stop_last=False, it is an ordinary node and goes first
    recorder.stop_last = False
    assert _stop_order([node, recorder], log, 0.2) == ["recorder stopped", "node stopped"]
    # and with stop_last back on, the grace-then-recorder stage still holds in that order
    recorder.stop_last = None
    assert _stop_order([node, recorder], log, 0.2) == ["node stopped", "recorder stopped"]


def test_nodes_stop_one_at_a_time_clients_first(tmp_path):
    """A node started later (a controller) has exited before the one started before it (the
    simulator it talks to) is signalled: a slow client never sees its server leave. Signalled
    together, the quick server would be gone first."""
    log = tmp_path / "order.txt"
    assert _stop_order([_says(log, "server", 0), _says(log, "client", 0.4)], log, 0.0) == \
        ["client stopped", "server stopped"]
