"""The mission's command line and its run: fly the scenarios in order, write the outputs."""
from __future__ import annotations

import argparse
import math
import signal
import sys
import time
from pathlib import Path

from astrobee import config
from astrobee.scenario import Scenario, ScenarioError
from astrobee.task import SETTLE_BUDGET
from astrobee_bringup.series import Series

from .client import MissionClient
from .leg import fly_leg
from .progress import Progress
from .result import Interrupted, LegResult, finish_leg, write_outputs


def run_mission(scenarios: list[str], run_dir: Path, namespace: str = "",
                argv: list[str] | None = None, wall_timeout: float = 600.0,
                ready_timeout: float = 90.0, stream=None, handover: bool = False,
                await_recorder: bool = False, settle_budget: float = SETTLE_BUDGET,
                keep_going: bool = False) -> int:
    """Fly the scenarios in order in the running graph; write run_dir/summary.json + plots.
    Returns the process exit status (0 all legs succeeded, 1 failure, 130 interrupted; with
    keep_going every leg is flown whatever the verdict before it, and 0 says they all were:
    the verdicts are in summary.json, as the demo's PD-then-wmpc comparison wants)."""
    from roszen import runtime as roszen

    stop = {"flag": False}

    def handler(signum, frame):  # noqa: ARG001
        stop["flag"] = True

    old = {}
    if signal.getsignal(signal.SIGINT) is not None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                old[sig] = signal.signal(sig, handler)
            except ValueError:  # not the main thread
                pass
    for name in scenarios:
        Scenario.load(name)  # fail early on an unknown or invalid scenario
    args = list(argv or ["mission"])
    if "--ros-args" not in args:
        args += ["--ros-args"]
    args += ["-p", "use_sim_time:=true"]
    node = roszen.Node("mission", namespace="", argv=args)
    client = MissionClient(node, namespace, stop_flag=lambda: stop["flag"], handover=handover,
                           await_recorder=await_recorder)
    progress = Progress(stream)
    legs: list[LegResult] = []
    all_series: list[dict[str, Series]] = []
    status = "completed"
    code = 0
    try:
        for i, name in enumerate(scenarios):
            try:
                res = fly_leg(client, name, i > 0, progress, wall_timeout, ready_timeout,
                              settle_budget)
            except Interrupted:
                legs.append(getattr(client, "interrupted_result", None) or client_last(client, name))
                all_series.append(client.leg_series())
                status, code = "interrupted", 130
                break
            legs.append(res)
            all_series.append(client.leg_series())
            for w in client.watches.values():   # samples after this leg's end belong to no leg
                w.series = Series()
            progress.done(f"[mission] {name}: {'SUCCESS' if res.success else 'FAILED'}: {res.reason}"
                          + (f" ({res.duration:.1f} s sim, {res.real_time_factor:.1f}x real time)"
                             if res.duration is not None and res.real_time_factor else ""))
            if not res.success and not keep_going:
                code = 1
                status = "failed"
                break
    finally:
        data = write_outputs(Path(run_dir), legs, all_series, status)
        if data.get("write_error"):
            print(f"[mission] {data['write_error']}", file=stream or sys.stdout, flush=True)
        try:
            node.destroy_node()
        except Exception:  # noqa: BLE001
            pass
        for sig, h in old.items():
            signal.signal(sig, h)
    # the last line names the cause: the launcher quotes it as the run's cause when we fail
    print(f"[mission] summary: {Path(run_dir) / 'summary.json'} "
          f"({'success' if data['success'] else status + ': ' + str(data.get('reason', ''))})",
          file=stream or sys.stdout, flush=True)
    return code


def client_last(client: MissionClient, name: str) -> LegResult:
    """The result of a leg interrupted before fly() returned one."""
    res = LegResult(scenario=name, reason="interrupted (SIGINT/SIGTERM)")
    finish_leg(client, res)
    res.success = False
    return res


def main(argv: list[str] | None = None) -> int:
    """`astrobee mission`: the arguments, then run_mission (exit status as it says); stopped
    (SIGINT) while it starts, before run_mission took the signal over: 130, no traceback."""
    try:
        return _main(argv)
    except KeyboardInterrupt:
        return 130


def _main(argv: list[str] | None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    own, _, ros = (argv[:argv.index("--ros-args")], None, argv[argv.index("--ros-args"):]) \
        if "--ros-args" in argv else (argv, None, [])
    p = argparse.ArgumentParser(prog="astrobee mission",
                                description="Fly scenarios in the running graph; write summary.json")
    p.add_argument("--scenario", action="append", required=True,
                   help="scenario to fly (repeat for several legs)")
    p.add_argument("--run-dir", default=None, help="output directory (default runs/<time>)")
    p.add_argument("--namespace", default="", help="robot namespace of a one-robot scenario "
                   "(a scenario's robots come from /sim/scenario)")
    p.add_argument("--timeout", type=float, default=600.0, help="wall seconds per leg")
    p.add_argument("--handover", action="store_true",
                   help="deterministic lockstep: the sim was started paused (sim_node "
                        "start_paused); each leg reset, handed over at a fixed sim time, run "
                        "in chunks")
    p.add_argument("--await-recorder", action="store_true",
                   help="with --handover: wait for a bag recorder on every topic of the sim")
    p.add_argument("--settle-budget", type=float, default=SETTLE_BUDGET,
                   help="s a leg may run past its plan's end to come to rest at its goal "
                        f"(default {SETTLE_BUDGET:g})")
    p.add_argument("--keep-going", action="store_true",
                   help="fly every leg whatever the verdict of the one before (exit 0 when all "
                        "were flown; the verdicts are in summary.json)")
    a = p.parse_args(own)
    if not (math.isfinite(a.settle_budget) and a.settle_budget >= 0):
        p.error(f"--settle-budget must be >= 0 s, got {a.settle_budget:g}")
    try:
        for name in a.scenario:
            Scenario.load(name)
    except (ScenarioError, config.ConfigError) as exc:
        print(f"astrobee mission: {exc}", file=sys.stderr)
        return 2
    run_dir = Path(a.run_dir) if a.run_dir else Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    return run_mission(a.scenario, run_dir, a.namespace, ["mission", *ros], wall_timeout=a.timeout,
                       handover=a.handover, await_recorder=a.await_recorder,
                       settle_budget=a.settle_budget, keep_going=a.keep_going)
