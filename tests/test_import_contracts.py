"""The layer contracts of docs/design.md (pyproject's [tool.importlinter]) hold: `lint-imports`
finds every contract kept (bringup > lab > libraries > core | runtime, the libraries
independent, no import cycles among sibling modules of the checked packages)."""
from __future__ import annotations

import subprocess
import sys
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
