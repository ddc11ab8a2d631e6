"""One-line failures: a node that cannot start ends the launch with one line naming
it and its cause, with no traceback from the others; the cause reaches summary.json; Ctrl-C
never prints a traceback (nor is it swallowed inside a zenoh callback); rejected
launches leave no run folder; --show-args, arguments anywhere, --port over the environment."""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time

import pytest

from conftest import ASTROBEE, HERE, graph_env, pid_alive

pytestmark = pytest.mark.graph
FAILING = str(HERE / "launch_files" / "failing_start.py")


def _no_traceback(lines):
    text = "\n".join(lines)
    assert "Traceback" not in text and "callback error" not in text, text[-3000:]


def test_node_that_cannot_start_ends_the_launch_with_one_line(procs, port, tmp_path):
    run_dir = tmp_path / "run"
    p = procs([ASTROBEE, "launch", FAILING, "--port", str(port), "--run-dir", str(run_dir),
               "--sigint-timeout", "5"], env=graph_env(port))
    assert p.wait(timeout=60) == 1
    last = p.lines[-1]
    assert last.endswith("error: 'broken' exited with code 1: broken: error: parameter rate "
                         "must be > 0, got -1"), p.lines[-8:]
    _no_traceback(p.lines + p.err)
    # the adder (a roszen node) and the stand-in mission were stopped cleanly
    assert "'adder' stopped (code 0)" in "\n".join(p.lines)
    data = json.loads((run_dir / "summary.json").read_text())
    assert data["cause"] == "'broken' exited with code 1: broken: error: parameter rate must " \
                            "be > 0, got -1"
    assert data["status"] == "failed"
    assert data["legs"][0]["reason"] == f"stopped: {data['cause']}"
    assert data["reason"] == data["legs"][0]["reason"]


SIM_ONLY = """
from astrobee_bringup.process_group import NodeSpec
def generate_nodes(ctx):
    return [NodeSpec("router", kind="router", command=["router", "--port", str(ctx.port)]),
            NodeSpec("sim_node", "astrobee_sim", "sim_node", parameters=[
                {"scenario": "node2_to_jem", "use_sim_time": True, "lockstep_timeout": 5000.0}])]
"""


def test_real_sim_node_with_a_bad_parameter(procs, port, tmp_path):
    """sim_node refusing a parameter: the launch's last line names it and the parameter. The
    value reaches sim_node from a launch description of the test's own: cargo_transport refuses
    its arguments before any process starts (bag_mass:=-3, lockstep_timeout:=5000: see
    test_rejected_launch_leaves_no_run_folder and tests/cli/test_launch_arguments.py)."""
    description = tmp_path / "sim_only.py"
    description.write_text(SIM_ONLY)
    p = procs([ASTROBEE, "launch", str(description), "--port", str(port),
               "--run-dir", str(tmp_path / "run")], env=graph_env(port))
    assert p.wait(timeout=120) == 1
    assert "error: 'sim_node' exited with code 1: sim_node: error: parameter 'lockstep_timeout'" \
        in p.lines[-1], p.lines[-8:]
    _no_traceback(p.lines + p.err)


def test_sigint_is_never_swallowed_by_a_zenoh_callback(router):
    """A node that spends its time publishing /clock to itself (sim_node in lockstep): SIGINT
    ends it promptly, exit 0, no 'callback error ... KeyboardInterrupt', every time."""
    env = graph_env(router)
    for _ in range(4):
        proc = subprocess.Popen([sys.executable, str(HERE / "clock_loop_node.py")], env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                start_new_session=True, text=True)
        try:
            assert proc.stdout.readline().strip() == "looping"
            time.sleep(0.3)
            proc.send_signal(signal.SIGINT)
            out, _ = proc.communicate(timeout=20)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        assert proc.returncode == 0, out
        _no_traceback(out.splitlines())


def test_ctrl_c_during_the_launch_gives_no_traceback(procs, port, tmp_path):
    p = procs([ASTROBEE, "launch", FAILING, "bad:=false", "--port", str(port),
               "--run-dir", str(tmp_path / "run")], env=graph_env(port))
    p.wait_line("mission up")
    p.wait_line("adder ready")
    p.signal(signal.SIGINT)
    assert p.wait(timeout=60) == 0, p.lines[-10:]
    _no_traceback(p.lines + p.err)
    assert "cause" not in json.loads((tmp_path / "run" / "summary.json").read_text())


@pytest.mark.parametrize("args, says", [
    (["cargo_transport", "controller:=lqr"], "controller must be"),
    (["cargo_transport", "scenario:=no_such_place"], "unknown scenario"),
    (["cargo_transport", "lockstep_timeout:=-1"], "lockstep_timeout must be > 0"),
    (["cargo_transport", "bag_mass:=-3"], "bag_mass must be 0.05..100 kg, got '-3'"),
    (["cargo_transport", "scenaro:=node2_to_jem"], "unknown launch argument scenaro"),
    (["cargo_transport", "--port", "abc"], "argument --port: invalid int value: 'abc'"),
])
def test_rejected_launch_leaves_no_run_folder(procs, tmp_path, args, says):
    run_dir = tmp_path / "runs" / "t1"
    p = procs([ASTROBEE, "launch", *args, "--run-dir", str(run_dir)])
    assert p.wait(timeout=60) == 1
    assert len(p.err) == 1 and says in p.err[0], p.err
    assert not (tmp_path / "runs").exists()
    # the default runs/<time> too: nothing appears in the working directory
    p = procs([ASTROBEE, "launch", *args], cwd=tmp_path)
    assert p.wait(timeout=60) == 1
    assert not (tmp_path / "runs").exists()


def test_gui_without_display_is_rejected_up_front(procs, tmp_path):
    env = dict(os.environ)
    env.pop("DISPLAY", None)
    env.pop("WAYLAND_DISPLAY", None)
    p = procs([ASTROBEE, "launch", "cargo_transport", "gui:=true"], env=env, cwd=tmp_path)
    assert p.wait(timeout=60) == 1
    assert len(p.err) == 1 and "gui:=true needs a display" in p.err[0]
    assert p.lines == [] and not (tmp_path / "runs").exists()


def test_show_args_lists_declared_arguments(procs):
    p = procs([ASTROBEE, "launch", "cargo_transport", "--show-args"])
    assert p.wait(timeout=30) == 0
    out = "\n".join(p.lines)
    assert out.startswith("Arguments (pass arguments as '<name>:=<value>'):")
    assert "    'scenario':" in out and "(default: 'node2_to_jem')" in out
    from astrobee_control import registry          # the controller's choices: every law
    assert "    'controller':" in out and registry.choices_text(" | ") in out
    p = procs([ASTROBEE, "launch", FAILING, "-s"])
    assert p.wait(timeout=30) == 0 and "    'bad':" in p.lines


def test_launch_arguments_anywhere_and_port_beats_the_environment(procs, port, tmp_path):
    """name:=value before and after options; a ZENOH_CONFIG_OVERRIDE naming another router does
    not pull the launcher's nodes away from --port's router (the adder is seen there)."""
    env = graph_env(port)
    env["ZENOH_CONFIG_OVERRIDE"] = 'connect/endpoints=["tcp/127.0.0.1:9"];scouting/multicast/enabled=false'
    p = procs([ASTROBEE, "launch", "--port", str(port), FAILING, "--run-dir",
               str(tmp_path / "run"), "bad:=false", "--sigint-timeout", "5"], env=env)
    p.wait_line("adder ready")
    nodes = subprocess.run([ASTROBEE, "node", "list"], env=graph_env(port), capture_output=True,
                           text=True, timeout=30)
    assert "/adder" in nodes.stdout.split(), nodes
    assert "[broken]" not in "\n".join(p.lines)      # bad:=false was read after the options
    p.signal(signal.SIGINT)
    assert p.wait(timeout=60) == 0


def test_killed_node_is_the_cause_without_stale_lines(tmp_path):
    """kill -9 of a required node: the cause names the signal, not an old log line."""
    import io
    import threading

    from astrobee_bringup.process_group import Launcher, NodeSpec
    code = ("import time\nprint('[WARN] position error 0.2 m', flush=True)\nprint('up', flush=True)\n"
            "while True: time.sleep(0.05)")
    specs = [NodeSpec("victim", argv=[sys.executable, "-c", code]),
             NodeSpec("bystander", required=False,
                      argv=[sys.executable, "-c", "import time\nwhile True: time.sleep(0.05)"])]
    out = io.StringIO()
    launcher = Launcher(specs, out=out, colour=False, stop_grace=0.0, sigint_timeout=5.0)

    def kill_when_up():
        deadline = time.monotonic() + 30
        while not re.search(r"\[victim\]\s+up", out.getvalue()) and time.monotonic() < deadline:
            time.sleep(0.05)
        os.kill(launcher.procs[0][1].pid, signal.SIGKILL)
    threading.Thread(target=kill_when_up, daemon=True).start()
    assert launcher.run() == 1
    assert launcher.cause == "'victim' killed by SIGKILL", out.getvalue()
    assert out.getvalue().rstrip().endswith("error: 'victim' killed by SIGKILL")
    assert all(p.poll() is not None for _, p in launcher.procs)
