"""The layer contracts of docs/design.md (pyproject's [tool.importlinter]) hold: `lint-imports`
finds every contract kept (bringup > lab > libraries > core | runtime, the libraries
independent, no import cycles among sibling modules of the checked packages), with no import
exempted from any contract."""
from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINT = Path(sys.executable).parent / "lint-imports"


def test_import_contracts_are_kept(tmp_path):
    # from outside the repository: its ament package folders (astrobee_control/...) would
    # otherwise shadow the installed packages as namespace packages
    out = subprocess.run([str(LINT), "--no-cache", str(ROOT / "pyproject.toml")], cwd=tmp_path,
                         capture_output=True, text=True, timeout=240)
    text = out.stdout + out.stderr
    assert out.returncode == 0 and "BROKEN" not in text, text[-4000:]
    assert " kept, 0 broken." in text, text[-2000:]


def test_no_contract_exempts_an_import():
    """Each contract holds for every import: none lists `ignore_imports`, and the acyclic one
    covers the runtime too."""
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    assert [c["name"] for c in cfg["contracts"] if c.get("ignore_imports")] == []
    acyclic = next(c for c in cfg["contracts"] if c["type"] == "acyclic_siblings")
    assert {"roszen", "astrobee", "astrobee_sim", "astrobee_planning", "astrobee_control",
            "astrobee_lab", "astrobee_bringup"} <= set(acyclic["ancestors"])
