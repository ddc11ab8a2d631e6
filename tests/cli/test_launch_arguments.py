"""Launch arguments of cargo_transport checked before anything starts: each bad
value (a bad controller_params file too) is one line naming the argument, exit 1, no process
started and no run folder (nor a rosbag2_<time>/ in the working directory); numbers reach
sim_node as YAML floats; the mission stopped while it starts exits 130 without a traceback."""
from __future__ import annotations

import subprocess

import pytest
import yaml

from conftest import ASTROBEE

from astrobee_bringup import launcher, process_group
from astrobee_bringup.cli import launch_main
from astrobee_bringup.launch import cargo_transport

BAD = [
    (["bag_dir:="], "bag_dir must be a folder path, got ''"),
    (["bag_dir:=/proc/x"], "bag_dir /proc/x: cannot make a folder in /proc"),
    (["bag_dir:=/no_such_folder/b"], "bag_dir /no_such_folder/b: /no_such_folder is not a folder"),
    (["record:=maybe"], "record must be true or false"),
    (["gui:="], "gui must be true or false"),
    (["mission:=2"], "mission must be true or false"),
    (["demo:=yess"], "demo must be true or false"),
    (["video:=True!"], "video must be true or false"),
    (["seed:="], "seed must be an integer 0..2**63-1, got ''"),
    (["seed:=99999999999999999999"], "seed must be an integer 0..2**63-1"),
    (["seed:=-1"], "seed must be an integer 0..2**63-1"),
    (["seed:=1.5"], "seed must be an integer 0..2**63-1"),
    (["bag_mass:=1e-300"], "bag_mass must be 0.05..100 kg, got '1e-300'"),
    (["lockstep_timeout:=1e300"], "lockstep_timeout must be > 0 and <= 3600 s, got '1e300'"),
    (["lockstep_timeout:=nan"], "lockstep_timeout must be > 0"),
    (["lockstep_timeout:=0"], "lockstep_timeout must be > 0"),
]


@pytest.fixture
def no_start(monkeypatch):
    """Any process start fails the test: the arguments must be refused before."""
    def started(*_a, **_k):
        raise AssertionError("a process was started")
    monkeypatch.setattr(process_group.Launcher, "run", started)
    monkeypatch.setattr(subprocess, "Popen", started)


@pytest.mark.parametrize("args, says", BAD, ids=[a[0] for a, _ in BAD])
def test_a_bad_argument_is_one_line_before_anything(args, says, tmp_path, monkeypatch, capsys,
                                                    no_start):
    monkeypatch.chdir(tmp_path)
    code = launch_main(["cargo_transport", *args, "--port", "1"])
    out, err = capsys.readouterr()
    assert code == 1
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("astrobee launch: ") and says in lines[0], err
    assert "Traceback" not in out + err
    assert list(tmp_path.iterdir()) == []          # no runs/<time>, no rosbag2_<time>


# controller_params:= files (written into a folder of their own): content -> what the line says
BAD_CONTROLLER_PARAMS = [
    (None, "no such file"),
    ("pair_gov: {lever: true\n  clearance: [\n", "not valid YAML: expected ',' or '}', but "
                                                   "got ':' (line 2, column 12)"),
    ("", "does not hold a mapping <law>: {name: value}"),
    ("- pair_gov\n", "does not hold a mapping <law>: {name: value}"),
    ("lqr: {gain: 1}\n", "'lqr' is not a controller (mpc, pair"),
    ("pair_gov: 3\n", "pair_gov must map parameter names to values, got 3"),
    ("pair_gov: {clearence: 0.3}\n", "pair_gov has no parameter 'clearence' (did you mean "
                                     "'clearance'?)"),
    ("pair_gov: {clearance: far}\n", "pair_gov parameter 'clearance': expected double, got "
                                     "string value 'far'"),
    ("pair_gov: {lever: 1}\n", "pair_gov parameter 'lever': expected bool"),
    ("pair_gov: {clearance: -1}\n", "pair_gov: clearance must be a finite number >= 0, got -1"),
    ("pair_gov: {att_slow: 0.9, att_stop: 0.2}\n", "pair_gov: att_slow (0.9) must be below "
                                                   "att_stop (0.2)"),
    # a law no robot flies (node2_to_jem: PD) is checked all the same
    ("pd: {}\nmpc: {samples: 1.5}\n", "mpc parameter 'samples': expected integer"),
]


@pytest.mark.parametrize("content, says", BAD_CONTROLLER_PARAMS,
                         ids=[says.split(":")[0][:30] for _, says in BAD_CONTROLLER_PARAMS])
def test_a_bad_controller_params_file_is_one_line_before_anything(content, says, tmp_path,
                                                                  monkeypatch, capsys, no_start):
    given = tmp_path / "files" / "params.yaml"
    given.parent.mkdir()
    if content is not None:
        given.write_text(content)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    code = launch_main(["cargo_transport", f"controller_params:={given}", "--port", "1"])
    out, err = capsys.readouterr()
    assert code == 1
    lines = err.splitlines()
    assert len(lines) == 1 and says in lines[0], err
    assert lines[0].startswith(f"astrobee launch: controller_params {given}: "), err
    assert "Traceback" not in out + err
    assert list(work.iterdir()) == []              # no runs/<time>, no rosbag2_<time>


@pytest.mark.parametrize("what, says", [("folder", "not a file"),
                                        ("unreadable", "cannot read it (Permission denied)"),
                                        ("binary", "not a text (UTF-8) file"),
                                        ("", "controller_params must be a YAML file path, got ''")])
def test_a_controller_params_file_that_cannot_be_read_is_one_line(what, says, tmp_path,
                                                                  monkeypatch, capsys, no_start):
    given = tmp_path / "params.yaml"
    if what == "folder":
        given.mkdir()
    elif what == "binary":
        given.write_bytes(b"\xff\xfe\x00")
    elif what == "unreadable":                      # (as root chmod 000 reads all the same)
        given.write_text("pd: {}\n")
        real = cargo_transport.load_yaml

        def denied(path):
            if path == given:
                raise PermissionError(13, "Permission denied")
            return real(path)
        monkeypatch.setattr(cargo_transport, "load_yaml", denied)
    monkeypatch.chdir(tmp_path)
    code = launch_main(["cargo_transport", f"controller_params:={given if what else ''}",
                        "--port", "1"])
    err = capsys.readouterr().err
    assert code == 1 and len(err.splitlines()) == 1 and says in err, err
    assert not (tmp_path / "runs").exists()


def test_controller_params_is_a_declared_argument():
    assert "controller_params" in launcher.declared_arguments("cargo_transport")
    text = launcher.format_arguments("cargo_transport")
    assert "    'controller_params':" in text and "config/controllers.yaml" in text


def test_the_real_command_refuses_bag_dir_in_proc(tmp_path):
    """As the attack did it: the recorder could not make /proc/x; now the launcher says so."""
    p = subprocess.run([ASTROBEE, "launch", "cargo_transport", "bag_dir:=/proc/x",
                        "--run-dir", str(tmp_path / "run")], capture_output=True, text=True,
                       timeout=60, cwd=tmp_path)
    assert p.returncode == 1
    lines = p.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("astrobee launch: bag_dir /proc/x: cannot make "
                                                   "a folder in /proc"), p.stderr
    assert p.stdout == "" and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("word", ["true", "False", "yes", "NO", "1", "0", "on", "off"])
def test_flag_words_are_taken(word, tmp_path):
    ctx = launcher.LaunchContext({"record": word, "gui": "false", "video": word},
                                 tmp_path, tmp_path / "run", False, 1)
    cargo_transport.check_arguments(ctx)


def test_numbers_reach_sim_node_as_yaml_floats(tmp_path):
    """lockstep_timeout:=1e-5 (an exponent without a dot: a string to YAML 1.1) reaches sim_node
    as a float; a seed as an integer."""
    ctx = launcher.LaunchContext({"lockstep_timeout": "1e-5", "seed": "9223372036854775807",
                                  "record": "false", "mission": "false"},
                                 launcher.find_config_dir(), tmp_path / "run", False, 1)
    sim = next(s for s in cargo_transport.generate_nodes(ctx) if s.name == "sim_node")
    argv = process_group.Launcher([sim], use_ros2=False, port=1, run_dir=tmp_path).argv_for(sim)
    given = dict(argv[i + 1].split(":=", 1) for i, a in enumerate(argv) if a == "-p")
    assert yaml.safe_load(given["lockstep_timeout"]) == 1e-5
    assert yaml.safe_load(given["seed"]) == 2**63 - 1


def test_yaml_float_round_trips():
    for v in (1e-5, 1e-300, 0.5, 3.0, 1e16, 3600.0, 123456.789):
        text = cargo_transport._yaml_float(v)
        assert isinstance(yaml.safe_load(text), float) and yaml.safe_load(text) == v, text


def test_mission_stopped_while_starting_exits_130_quietly(monkeypatch, capsys):
    """SIGINT from the launcher before run_mission took the signal over (here: while the
    scenarios load) is exit 130, nothing printed (it was a KeyboardInterrupt traceback)."""
    from astrobee_bringup.mission import cli

    def interrupted(*_a, **_k):
        raise KeyboardInterrupt
    monkeypatch.setattr(cli.Scenario, "load", interrupted)
    assert cli.main(["--scenario", "node2_to_jem"]) == 130
    out, err = capsys.readouterr()
    assert out == "" and err == ""
