"""The Task's verdict of a recorded flight agrees with the mission's summary: mission client +
planner_node + pd_controller_node + recorder, each its own process, with sim_node on its
numpy rigid-body backend (lockstep, started paused; the mission hands the leg over once the
recorder has every sim topic), then the bag read back and judged by astrobee.task."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

roszen = pytest.importorskip("roszen")
from roszen import testing  # noqa: E402

pytestmark = pytest.mark.graph
ROOT = Path(__file__).resolve().parents[2]

Q = [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]
HOP = {"description": "hop in Node 2 with a bag (lab tests)", "flight_mode": "nominal",
       "robots": [{"name": "", "position": [10.95, 0.5, 4.84], "orientation": Q}],
       "bag": {"model": "rigid", "variant": "front", "mass": 10.0},
       "goal": {"position": [10.95, -0.3, 4.84], "orientation": Q}}


# nominal tolerances, and a strict copy of the nominal mode that no leg meets, so the mission fails
# the leg on its final errors after the controller's settle time. 1e-12 m / rad: the noise-free
# rigid backend converges towards machine precision (final position error 6.9e-11 m at the end of
# the budget, every run; the attitude error rounds to 0 or 3e-8 rad), so 1e-9 was met once, with
# the attitude at 0 for 2 s
TOLERANCES = {"nominal": None, "strict": 1e-12}


@pytest.mark.parametrize("tolerance", list(TOLERANCES))
def test_task_verdict_of_the_recording_agrees_with_the_mission(tmp_path, tolerance):
    cfg = tmp_path / "config"
    shutil.copytree(ROOT / "config", cfg)
    tol = TOLERANCES[tolerance]
    if tol is not None:
        text = (cfg / "astrobee.yaml").read_text()
        text = text.replace("tolerance_pos: 0.2\n", f"tolerance_pos: {tol}\n", 1)
        text = text.replace("tolerance_att: 0.3491\n", f"tolerance_att: {tol}\n", 1)
        (cfg / "astrobee.yaml").write_text(text)
    (cfg / "scenarios" / "lab_hop.yaml").write_text(yaml.safe_dump(HOP))
    run = tmp_path / "run"
    run.mkdir()
    procs = []
    with testing.router() as port:
        env = dict(testing.zenoh_env(port), ASTROBEE_CONFIG_DIR=str(cfg))
        py = sys.executable
        try:
            for argv in ([py, "-m", "astrobee_sim.sim_node", "--ros-args", "-p", "backend:=rigid",
                          "-p", "scenario:=lab_hop", "-p", "clock_mode:=lockstep",
                          "-p", "start_paused:=true"],
                         [py, "-m", "astrobee_planning.planner_node"],
                         [py, "-m", "astrobee_control.pd_controller_node", "--ros-args",
                          "-p", "use_sim_time:=true"],
                         [py, "-m", "astrobee_bringup.cli", "bag", "record", "-a", "-o",
                          str(run / "bag")]):
                procs.append(testing.spawn(argv, env, stdout=subprocess.DEVNULL,
                                           stderr=subprocess.DEVNULL))
            mission = subprocess.run([py, "-m", "astrobee_bringup.mission", "--scenario", "lab_hop",
                                      "--run-dir", str(run), "--timeout", "120",
                                      # the leg starts once the recorder has every sim topic:
                                      # the bag holds every sample the mission judged
                                      "--handover", "--await-recorder"], env=env,
                                     capture_output=True, text=True, timeout=180)
        finally:
            for p in reversed(procs):
                testing.stop(p, timeout=5.0)
    summary = json.loads((run / "summary.json").read_text())
    leg = summary["legs"][0] if "legs" in summary else summary

    from astrobee.scenario import Scenario
    from astrobee.task import Task
    from astrobee_lab.recorded import judge_bag
    sc = Scenario.from_dict(HOP, "lab_hop")
    task = Task.from_scenario(sc)
    if tol is not None:
        task.tolerance_position = task.tolerance_attitude = tol
    monitor = judge_bag(run / "bag", task)
    ok, cause = monitor.verdict()
    assert ok == leg["success"] == (mission.returncode == 0) == (tol is None), \
        (cause, leg["reason"])
    assert cause == leg["reason"]
    m = monitor.metrics()
    assert m["contacts"] == leg["contacts"]
    assert m["final_position_error"] == pytest.approx(leg["final_position_error"], abs=0.01)
    assert m["rms_position_error"] == pytest.approx(leg["rms_position_error"], abs=0.005)
    assert m["min_robot_clearance"] == pytest.approx(leg["min_robot_clearance"], abs=0.01)
