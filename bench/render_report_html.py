"""A study's report.html rendered by a real headless Chromium (the distribution's `chromium`
package; `.ci/run` calls this after `make test`): a screenshot with no console error.

    .venv/bin/python bench/render_report_html.py [REPORT.html] [--out SHOT.png]

Without REPORT.html it flies studies/smoke.yaml (4 short flights, in process) into a temporary
study folder and checks its report. Chromium missing: `apt-get install chromium` is tried (as
root, or through `sudo -n`); when that fails too the check prints one `skip:` line and exits 0.
Chromium runs with a fresh profile, no network services, no GPU, no sandbox (CI containers), and
logs the page's console to stderr (--enable-logging=stderr --v=1: every console message, level
not said); the page's own inline check logs `REPORT ERROR: plot not decoded` for a plot that did
not decode and `report loaded: N plots, M tables` once loaded. Exit 1 with the lines
found when a console error, no load line, or a blank screenshot shows.
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--no-first-run", "--disable-component-update", "--disable-sync",
         "--disable-default-apps", "--enable-logging=stderr", "--v=1", "--hide-scrollbars",
         "--window-size=1280,1600", "--virtual-time-budget=5000"]


def find_browser() -> str | None:
    return next((shutil.which(b) for b in BROWSERS if shutil.which(b)), None)


def install_browser() -> str | None:
    """apt-get install chromium (root, or sudo -n); the browser's path, None when it failed."""
    if not shutil.which("apt-get"):
        return None
    sudo = [] if os.geteuid() == 0 else (["sudo", "-n"] if shutil.which("sudo") else None)
    if sudo is None:
        return None
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    for cmd in (["apt-get", "update", "-q"], ["apt-get", "install", "-y", "-q", "chromium"]):
        r = subprocess.run(sudo + cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                           text=True, timeout=900)
        if r.returncode != 0 and cmd[1] == "install":
            return None
    return find_browser()


def smoke_report(folder: Path) -> Path:
    """The report.html of studies/smoke.yaml flown into `folder`."""
    r = subprocess.run([sys.executable, "-m", "astrobee_lab.study.cli", "run",
                        str(ROOT / "studies" / "smoke.yaml"), "--out", str(folder),
                        "--workers", "1", "--quiet"], capture_output=True, text=True, timeout=900)
    if r.returncode != 0:
        raise SystemExit(f"render_report_html: the smoke study failed: {r.stderr.strip()[-500:]}")
    return folder / "report.html"


def console_problems(log: str) -> tuple[list[str], bool]:
    """(the console's error lines, whether the page's 'report loaded' line came)."""
    console = [ln for ln in log.splitlines() if ":CONSOLE" in ln]
    # the log does not say a message's level: the page's own errors carry "REPORT ERROR", the
    # browser's are uncaught exceptions and resources that failed to load
    errors = [ln for ln in console if re.search(r"REPORT ERROR|Uncaught|Failed to load", ln)]
    return errors, any("report loaded" in ln for ln in console)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("report", nargs="?", help="report.html (default: the smoke study's)")
    p.add_argument("--out", help="screenshot PNG (default: beside the report)")
    a = p.parse_args(argv)
    browser = find_browser() or install_browser()
    if browser is None:
        print("skip: no Chromium and `apt-get install chromium` failed: report.html not "
              "rendered in a browser")
        return 0
    with tempfile.TemporaryDirectory(prefix="report_html_") as tmp:
        report = Path(a.report) if a.report else smoke_report(Path(tmp) / "study")
        if not report.is_file():
            print(f"render_report_html: no {report}", file=sys.stderr)
            return 1
        shot = Path(a.out) if a.out else report.with_name("report_screenshot.png")
        profile = Path(tmp) / "profile"
        cmd = [browser, *FLAGS, f"--user-data-dir={profile}", f"--screenshot={shot}",
               report.resolve().as_uri()]
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
        errors, loaded = console_problems(r.stderr + r.stdout)
        blank = True
        if shot.is_file():
            import numpy as np
            from PIL import Image
            with Image.open(shot) as im:
                blank = float(np.asarray(im.convert("L"), float).std()) < 5.0
        ok = r.returncode == 0 and loaded and not errors and not blank
        version = subprocess.run([browser, "--version"], capture_output=True, text=True).stdout
        print(f"report.html in {version.strip() or browser}: "
              f"{'ok' if ok else 'FAILED'}: screenshot {shot}"
              + ("" if shot.is_file() else " (not written)") + (" blank" if blank else "")
              + f", console errors {len(errors)}, page {'loaded' if loaded else 'NOT loaded'}")
        for ln in errors[:20]:
            print(f"  {ln}")
        if not ok and not errors:
            print("\n".join(f"  {ln}" for ln in (r.stderr.strip().splitlines())[-15:]))
        if a.report is None and shot.is_file():      # keep the smoke screenshot out of /tmp
            keep = ROOT / "runs" / "report_screenshot.png"
            keep.parent.mkdir(exist_ok=True)
            shutil.copy(shot, keep)
            print(f"  kept {keep}")
        return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
