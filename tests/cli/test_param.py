"""`astrobee param list | get | set | dump` against a node of ours in another process (the
adder), through its rcl_interfaces parameter services; one-line errors for unknown nodes,
parameters and values that do not fit."""
from __future__ import annotations

import subprocess
import sys

import pytest
import yaml

from conftest import ASTROBEE, HERE, Proc, graph_env

pytestmark = pytest.mark.graph


@pytest.fixture(scope="module")
def graph():
    """A router and the adder node (parameters increment, label, gain, weights)."""
    from roszen import testing
    with testing.router() as port:
        env = graph_env(port)
        adder = Proc([sys.executable, str(HERE / "adder_node.py")], env=env)
        try:
            adder.wait_line("adder ready")
            yield env
        finally:
            adder.kill()


def run(env, *args):
    return subprocess.run([ASTROBEE, "param", *args], env=env, capture_output=True, text=True,
                          timeout=30)


def assert_one_line_error(r, *words):
    assert r.returncode != 0
    assert r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("astrobee param "), r.stderr
    for w in words:
        assert w in lines[0], lines[0]


def test_list_get_set_get_dump(graph):
    r = run(graph, "list", "/adder")
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["gain", "increment", "label", "use_sim_time", "weights"]
    r = run(graph, "list", "--param-type")         # every node, its name as a heading
    assert "/adder:\n" in r.stdout and "  weights (type: double array)" in r.stdout

    assert run(graph, "get", "/adder", "gain").stdout == "Double value is: 0.5\n"
    assert run(graph, "get", "adder", "label").stdout == "String value is: adder\n"
    assert run(graph, "get", "/adder", "weights").stdout == "Double values are: [1.0, 2.0]\n"

    r = run(graph, "set", "/adder", "gain", "2.25")
    assert (r.returncode, r.stdout) == (0, "Set parameter successful\n"), r.stderr
    assert run(graph, "get", "/adder", "gain").stdout == "Double value is: 2.25\n"
    assert run(graph, "set", "/adder", "label", "summing").returncode == 0
    assert run(graph, "set", "/adder", "weights", "[3, 4.5]").returncode == 0
    assert run(graph, "get", "/adder", "weights", "--hide-type").stdout == "[3.0, 4.5]\n"

    # the new value is the node's: its count now steps by the new increment
    assert run(graph, "set", "/adder", "increment", "7").returncode == 0
    echo = subprocess.run([ASTROBEE, "topic", "echo", "/adder/count", "--field", "data",
                           "--once"], env=graph, capture_output=True, text=True, timeout=30)
    first = int(echo.stdout.split()[0])
    echo = subprocess.run([ASTROBEE, "topic", "echo", "/adder/count", "--field", "data",
                           "--once"], env=graph, capture_output=True, text=True, timeout=30)
    second = int(echo.stdout.split()[0])
    assert second > first and (second - first) % 7 == 0, (first, second)

    dumped = yaml.safe_load(run(graph, "dump", "/adder").stdout)
    assert dumped == {"/adder": {"ros__parameters": {
        "gain": 2.25, "increment": 7, "label": "summing", "use_sim_time": False,
        "weights": [3.0, 4.5]}}}


def test_bad_input_one_line_errors(graph):
    before = run(graph, "get", "/adder", "increment").stdout
    assert before.startswith("Integer value is: ")
    assert_one_line_error(run(graph, "get", "/nobody", "gain"), "Node not found", "/nobody")
    assert_one_line_error(run(graph, "list", "/nobody"), "Node not found")
    assert_one_line_error(run(graph, "dump", "/nobody"), "Node not found")
    assert_one_line_error(run(graph, "set", "/nobody", "gain", "1.0"), "Node not found")
    assert_one_line_error(run(graph, "get", "/adder", "nope"), "Parameter not set", "nope")
    assert_one_line_error(run(graph, "set", "/adder", "nope", "1"), "failed", "nope")
    assert_one_line_error(run(graph, "set", "/adder", "increment", "abc"), "failed", "integer")
    assert_one_line_error(run(graph, "set", "/adder", "gain", "{a: 1}"), "not a parameter value")
    assert_one_line_error(run(graph, "set", "/adder", "gain", "11.0"), "failed", "<= 10")
    assert_one_line_error(run(graph, "describe", "/adder", "nope"), "Parameter not set", "nope")
    # a rejected set changed nothing
    assert run(graph, "get", "/adder", "increment").stdout == before


def test_describe_shows_type_range_and_constraints(graph):
    r = run(graph, "describe", "/adder", "gain", "label")
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == [
        "Parameter name: gain", "  Type: double", "  Description: a scale", "  Constraints:",
        "    Min value: 0", "    Max value: 10",
        "Parameter name: label", "  Type: string", "  Constraints:"]
