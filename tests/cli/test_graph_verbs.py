"""The ros2-style verbs from a shell against a live graph: router, `topic pub` in one process,
`topic echo` in another, `service call` to a node of ours, `node list` showing them, and
one-line errors for bad input."""
from __future__ import annotations

import signal
import subprocess

import pytest

from conftest import ASTROBEE, HERE, Proc, graph_env

pytestmark = pytest.mark.graph


@pytest.fixture(scope="module")
def graph():
    """A router and the adder node, shared by the tests of this module."""
    from roszen import testing
    with testing.router() as port:
        env = graph_env(port)
        adder = Proc([sys_python(), str(HERE / "adder_node.py")], env=env)
        try:
            adder.wait_line("adder ready")
            yield env
        finally:
            adder.kill()


def sys_python():
    import sys
    return sys.executable


def run(env, *args, timeout=30):
    return subprocess.run([ASTROBEE, *args], env=env, capture_output=True, text=True,
                          timeout=timeout)


def test_pub_in_one_process_echo_in_another(graph, procs):
    echo = procs([ASTROBEE, "topic", "echo", "/chatter", "std_msgs/msg/String"], env=graph)
    pub = procs([ASTROBEE, "topic", "pub", "-r", "20", "-n", "talker", "/chatter",
                 "std_msgs/msg/String", "{data: hello world}"], env=graph)
    assert pub.wait_line("publisher: beginning loop")
    assert pub.wait_line("publishing #1: std_msgs.msg.String(data='hello world')")
    echo.wait_line("data: hello world")
    echo.wait_line("---")
    # echo without a type finds it in the graph; --once exits by itself
    once = run(graph, "topic", "echo", "/chatter", "--once")
    assert once.returncode == 0, once.stderr
    assert once.stdout == "data: hello world\n---\n"
    nodes = run(graph, "node", "list")
    assert nodes.returncode == 0
    assert {"/adder", "/talker"} <= set(nodes.stdout.split())
    assert not any("_roszen_cli" in n for n in nodes.stdout.split())
    assert any("_roszen_cli" in n for n in run(graph, "node", "list", "-a").stdout.split())
    topics = run(graph, "topic", "list", "-t").stdout.splitlines()
    assert "/chatter [std_msgs/msg/String]" in topics
    info = run(graph, "topic", "info", "/chatter").stdout.splitlines()
    assert info[0] == "Type: std_msgs/msg/String"
    assert "Publisher count: 1" in info and "Subscription count: 1" in info
    echo.signal(signal.SIGINT)
    assert echo.wait() == 0
    pub.signal(signal.SIGINT)
    assert pub.wait() == 0


def test_pub_once_waits_for_subscriber_and_exits(graph, procs):
    echo = procs([ASTROBEE, "topic", "echo", "/once", "std_msgs/msg/Int64", "--once"],
                 env=graph)
    p = run(graph, "topic", "pub", "--once", "/once", "std_msgs/msg/Int64", "{data: 7}")
    assert p.returncode == 0, p.stderr
    assert p.stdout.splitlines()[:2] == ["publisher: beginning loop",
                                         "publishing #1: std_msgs.msg.Int64(data=7)"]
    assert echo.wait() == 0
    assert echo.lines == ["data: 7", "---"]


def test_service_call_to_our_node(graph):
    p = run(graph, "service", "call", "/add_two_ints", "example_interfaces/srv/AddTwoInts",
            "{a: 2, b: 40}")
    assert p.returncode == 0, p.stderr
    lines = p.stdout.splitlines()
    assert "requester: making request: example_interfaces.srv.AddTwoInts_Request(a=2, b=40)" \
        in lines
    i = lines.index("response:")
    assert lines[i + 1] == "example_interfaces.srv.AddTwoInts_Response(sum=42)"
    p = run(graph, "service", "call", "trigger", "std_srvs/srv/Trigger")
    assert p.returncode == 0, p.stderr
    assert "std_srvs.srv.Trigger_Response(success=True, message='triggered after" in p.stdout
    services = run(graph, "service", "list", "-t").stdout.splitlines()
    assert "/add_two_ints [example_interfaces/srv/AddTwoInts]" in services
    assert run(graph, "service", "type", "/trigger").stdout == "std_srvs/srv/Trigger\n"
    info = run(graph, "node", "info", "/adder").stdout
    assert "  Service Servers:\n" in info and "    /add_two_ints: example_interfaces/srv/AddTwoInts" \
        in info
    assert "    /adder/count: std_msgs/msg/Int32" in info


def test_echo_field_and_latched_topic(graph):
    p = run(graph, "topic", "echo", "/adder/mode", "--once")
    assert p.returncode == 0, p.stderr
    assert p.stdout == "data: adding\n---\n"          # latched: delivered to a late subscriber
    p = run(graph, "topic", "echo", "/adder/count", "--once", "--field", "data")
    assert p.returncode == 0, p.stderr
    value, sep = p.stdout.splitlines()
    assert int(value) > 0 and sep == "---"


def test_interface_show_and_list():
    p = subprocess.run([ASTROBEE, "interface", "show", "geometry_msgs/msg/PoseStamped"],
                       capture_output=True, text=True)
    assert p.returncode == 0
    assert "std_msgs/Header header\n\tbuiltin_interfaces/Time stamp\n\t\tint32 sec" in p.stdout
    p = subprocess.run([ASTROBEE, "interface", "list"], capture_output=True, text=True)
    assert "    astrobee_msgs/msg/FamCommand" in p.stdout.splitlines()
    assert "    example_interfaces/srv/AddTwoInts" in p.stdout.splitlines()


@pytest.mark.parametrize("argv,needle", [
    (["topic", "echo", "/no_such_topic", "--discovery-timeout", "0.5"],
     "Could not determine the type for the passed topic '/no_such_topic'"),
    (["topic", "info", "/no_such_topic"], "Unknown topic '/no_such_topic'"),
    (["topic", "pub", "/x", "std_msgs/msg/Nope", "{}"], "std_msgs/msg/Nope"),
    (["topic", "pub", "/x", "std_msgs/msg/String", "{dta: 1}"], "unknown field 'dta'"),
    (["topic", "pub", "/x", "std_msgs/msg/Int8", "{data: 1000}"], "out of range"),
    (["topic", "pub", "/x", "std_msgs/msg/String", "{data: [1"], "not valid YAML"),
    (["topic", "pub", "/x", "std_msgs/msg/String", "[1, 2]"], "YAML mapping"),
    (["topic", "pub", "-r", "0", "/x", "std_msgs/msg/String", "{}"], "positive number"),
    (["service", "call", "/no_such_service", "std_srvs/srv/Trigger", "--timeout", "0.5"],
     "service '/no_such_service' not available"),
    (["service", "call", "/add_two_ints", "std_srvs/srv/Trigger", "--timeout", "0.5"],
     "has type example_interfaces/srv/AddTwoInts"),
    (["service", "call", "/add_two_ints", "example_interfaces/srv/AddTwoInts", "{a: x}"],
     "field 'a'"),
    (["service", "call", "/add_two_ints", "std_msgs/msg/String"], "not a known service type"),
    (["interface", "show", "nope_msgs/msg/Nope"], "nope_msgs/msg/Nope"),
    (["node", "info", "/nobody"], "Unable to find node '/nobody'"),
])
def test_bad_input_one_line_error(graph, argv, needle):
    p = run(graph, *argv)
    assert p.returncode != 0
    err = p.stderr.strip().splitlines()
    assert len(err) == 1, p.stderr
    assert needle in err[0]
    assert err[0].startswith("astrobee ")


def test_hz_and_bw_report_the_publisher(graph, procs):
    hz = procs([ASTROBEE, "topic", "hz", "/adder/count"], env=graph)
    bw = procs([ASTROBEE, "topic", "bw", "/adder/count"], env=graph)
    line = hz.wait_line(lambda x: x.startswith("average rate:") and float(x.split()[-1]) > 0,
                        timeout=20)
    assert 5.0 < float(line.split()[-1]) < 20.0          # the adder publishes at 10 Hz
    assert hz.wait_line("window:")
    bw.wait_line("Subscribed to [/adder/count]")
    line = bw.wait_line(" from ", timeout=20)
    assert "B/s from" in line
    bw.wait_line("Message size mean: 8 B")              # Int32 CDR: 4-byte header + 4
    for p in (hz, bw):
        p.signal(signal.SIGINT)
        assert p.wait() == 0


def test_run_registry_node_joins_graph_and_stops_on_sigint(graph, procs):
    node = procs([ASTROBEE, "run", "astrobee_planning", "planner_node", "--ros-args",
                  "-r", "__node:=planner_probe"], env=graph)
    deadline = __import__("time").monotonic() + 30
    while __import__("time").monotonic() < deadline:
        if "/planner_probe" in run(graph, "node", "list").stdout.split():
            break
        assert node.popen.poll() is None, node.err[-5:]
    else:
        raise AssertionError(f"planner_probe never joined: {node.err[-5:]}")
    node.signal(signal.SIGINT)
    assert node.wait(timeout=20) in (0, -signal.SIGINT, 130)
