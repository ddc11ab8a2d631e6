"""CLI verbs are entry points: `astrobee -h` is built from them, `bag -h` lists the bag's
sub-verbs (render included), and a verb a test fixture registers appears and runs."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from importlib.metadata import entry_points
from pathlib import Path

import pytest

from roszen.cli import registry

ASTROBEE = str(Path(sys.executable).parent / "astrobee")


def _run(*argv: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([ASTROBEE, *argv], capture_output=True, text=True, timeout=60, env=env)


def _listed(help_text: str) -> set[str]:
    """The verb names a generated -h lists (first word of each indented line)."""
    return {line.split()[0] for line in help_text.splitlines()
            if line.startswith("    ") and line.split() and not line.startswith("     ")}


def test_astrobee_help_lists_every_registered_verb():
    r = _run("-h")
    assert r.returncode == 0, r.stderr
    names = {ep.name for g in ("roszen.verbs", "astrobee.verbs") for ep in entry_points(group=g)}
    assert {"topic", "param", "bag", "run", "router", "launch", "study"} <= names
    assert _listed(r.stdout) == names, r.stdout


def test_bag_help_lists_its_sub_verbs_render_included():
    r = _run("bag", "-h")
    assert r.returncode == 0, r.stderr
    subs = {ep.name for ep in entry_points(group=registry.sub_group("bag"))}
    assert {"record", "play", "info", "reindex", "render"} <= subs
    assert _listed(r.stdout) == subs, r.stdout


def test_no_verb_prints_the_generated_usage_and_exits_2():
    r = _run()
    assert r.returncode == 2 and "launch" in r.stdout and "topic" in r.stdout


@pytest.fixture
def plugin_dist(tmp_path):
    """A distribution on PYTHONPATH registering `hello` (own parser), `echo2` (argparse) and a
    bag sub-verb `count`, with no file of the project edited."""
    (tmp_path / "hello_verbs.py").write_text(textwrap.dedent('''
        from roszen.cli.registry import Verb

        HELLO = Verb("say hello to NAME", "hello_verbs:hello")
        COUNT = Verb("count a bag's files", "hello_verbs:count")

        def hello(argv, prog):
            print(f"{prog} says hello to {' '.join(argv)}")
            return 0

        def count(argv):
            print(f"counted {len(argv)}")
            return 3

        def add_echo2(sub):
            p = sub.add_parser("echo2", help="echo twice")
            p.add_argument("word")
            p.set_defaults(func=lambda a: print(a.word * 2))
    '''))
    info = tmp_path / "hello_verbs-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: hello-verbs\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(textwrap.dedent("""
        [astrobee.verbs]
        hello = hello_verbs:HELLO

        [roszen.verbs]
        echo2 = hello_verbs:add_echo2

        [roszen.bag.verbs]
        count = hello_verbs:COUNT
    """))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def test_a_verb_registered_by_a_fixture_is_listed_and_runs(plugin_dist):
    r = _run("-h", env=plugin_dist)
    assert {"hello", "echo2", "launch", "topic"} <= _listed(r.stdout), r.stdout
    r = _run("hello", "world", env=plugin_dist)
    assert (r.returncode, r.stdout) == (0, "astrobee says hello to world\n"), r.stderr
    r = _run("echo2", "ab", env=plugin_dist)
    assert (r.returncode, r.stdout) == (0, "abab\n"), r.stderr
    assert "count" in _listed(_run("bag", "-h", env=plugin_dist).stdout)
    r = _run("bag", "count", "a", "b", env=plugin_dist)
    assert (r.returncode, r.stdout) == (3, "counted 2\n"), r.stderr


def test_a_broken_plugin_is_one_warning_and_the_rest_works(tmp_path):
    info = tmp_path / "broken_verbs-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: broken-verbs\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[astrobee.verbs]\nbroken = no_such_module_xyz:VERB\n")
    env = dict(os.environ, PYTHONPATH=str(tmp_path))
    r = _run("-h", env=env)
    assert r.returncode == 0 and "launch" in r.stdout
    assert r.stderr.count("\n") == 1 and "broken" in r.stderr and "Traceback" not in r.stderr
