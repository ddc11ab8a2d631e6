"""`make install` on a Python without a pybullet wheel (3.12+, Ubuntu 24.04) and without the
build prerequisites: one line saying what to install, non-zero exit, pip never started. The
venv's python is a stand-in script reporting 3.12 with no Python.h (nothing is installed)."""
from __future__ import annotations

import shutil
import subprocess

import pytest

from conftest import ROOT

FAKE_PY = """#!/bin/sh
echo "$*" >> "{log}"
case "$*" in
  *"import pybullet"*) exit 1 ;;
  *"sys.version_info < (3, 12)"*) exit 0 ;;
  *"sys.version_info[:2]"*) echo 3.12 ;;
  *sysconfig*) echo /nonexistent/include/python3.12 ;;
  *) exit 0 ;;
esac
"""


@pytest.mark.skipif(shutil.which("make") is None, reason="no make")
def test_install_without_build_prerequisites_is_one_line(tmp_path):
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    log = tmp_path / "calls.txt"
    py = venv / "bin" / "python"
    py.write_text(FAKE_PY.format(log=log))
    py.chmod(0o755)
    r = subprocess.run(["make", "-s", "-C", str(ROOT), "install", f"VENV={venv}"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode != 0
    ours = [line for line in r.stderr.splitlines() if line.startswith("make install:")]
    assert ours == ["make install: pybullet has no wheel for Python 3.12; building it needs g++ "
                    "and Python.h: sudo apt-get install build-essential python3.12-dev (or "
                    f"Python 3.11: rm -rf {venv}; make install PYTHON=python3.11)"], r.stderr
    assert "-m pip" not in log.read_text()          # nothing was installed
    assert not (venv / ".installed").exists()
