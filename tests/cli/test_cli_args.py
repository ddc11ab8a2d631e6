"""Bad numeric arguments of the roszen verbs: exit 1 with one line naming the argument.

Parsing fails before any node is created, so no router is needed.
"""
from __future__ import annotations

import pytest

from roszen.cli import main

T = "std_msgs/msg/String"


@pytest.mark.parametrize("argv, name, value", [
    (["topic", "hz", "/x", "-w", "0"], "-w/--window", "'0'"),
    (["topic", "hz", "/x", "--window", "-3"], "-w/--window", "'-3'"),
    (["topic", "bw", "/x", "-w", "-1"], "-w/--window", "'-1'"),
    (["topic", "pub", "/x", T, "-r", "-5"], "-r/--rate", "'-5'"),
    (["topic", "pub", "/x", T, "--rate", "-0.5"], "-r/--rate", "'-0.5'"),
    (["topic", "pub", "/x", T, "-r", "0"], "-r/--rate", "'0'"),
    (["topic", "pub", "/x", T, "-t", "-2"], "-t/--times", "'-2'"),
    (["topic", "echo", "/x", "--timeout", "-2"], "--timeout", "'-2'"),
])
def test_bad_number_is_one_line_exit_1(argv, name, value, capsys):
    assert main(argv, prog="roszen") == 1
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1, cap.err
    assert lines[0].startswith(f"roszen {argv[0]} {argv[1]}: argument {name}:") and value in lines[0]
    assert "usage" not in cap.err and cap.out == ""


def test_missing_argument_is_one_line_exit_1(capsys):
    assert main(["topic", "pub", "/x"], prog="roszen") == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "message_type" in err[0]


def test_help_still_prints_usage(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["topic", "hz", "-h"], prog="roszen")
    assert exc.value.code == 0
    assert "--window" in capsys.readouterr().out


DEEP_LIST = "[" * 3000 + "]" * 3000
DEEP_MAP = "{a: " * 3000 + "1" + "}" * 3000


@pytest.mark.parametrize("argv, needle", [
    (["topic", "pub", "chat ter", T, "{data: x}", "--once"], "invalid name '/chat ter'"),
    (["topic", "pub", "/a//b", T, "{data: x}", "--once"], "contains '//'"),
    (["topic", "pub", "-n", "bad name", "/x", T, "{data: x}", "--once"], "invalid node name 'bad name'"),
    (["topic", "echo", "chat ter"], "invalid name '/chat ter'"),
    (["service", "call", "/a//b", "std_srvs/srv/Trigger"], "contains '//'"),
    (["topic", "pub", "/x", T, DEEP_LIST, "--once"], "nested deeper than 100 levels"),
    (["topic", "pub", "/x", T, DEEP_MAP, "--once"], "nested deeper than 100 levels"),
    (["param", "set", "/x", "y", DEEP_LIST], "nested deeper than 100 levels"),
])
def test_bad_names_and_deep_yaml_are_one_line_exit_1(argv, needle, capsys, monkeypatch):
    # refused before joining a graph: an unreachable router must not even be tried
    monkeypatch.setenv("ZENOH_CONFIG_OVERRIDE", 'connect/endpoints=["tcp/127.0.0.1:1"]')
    assert main(argv, prog="roszen") == 1
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], cap.err[-500:]
    assert lines[0].startswith(f"roszen {argv[0]} {argv[1]}: ") and "Traceback" not in cap.err


def test_deep_yaml_in_ros_args_and_params_files_is_one_line(tmp_path):
    from roszen.args import RosArgsError, load_params_file, parse_args
    with pytest.raises(RosArgsError, match="nested deeper than 100 levels"):
        parse_args(["--ros-args", "-p", f"x:={DEEP_LIST}"])
    f = tmp_path / "deep.yaml"
    f.write_text("n:\n  ros__parameters:\n    x: " + DEEP_MAP + "\n")
    with pytest.raises(RosArgsError, match=f"parameter file {f}: YAML nested deeper"):
        load_params_file(str(f), "n", "/")
