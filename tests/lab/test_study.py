"""astrobee_lab.study: the sweep runner (serial, process pool, Ray), resume after a kill, bad
study files, and one row re-flown through the graph."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from astrobee_control import registry
from astrobee_lab.study import cli as study_cli
from astrobee_lab.study.run import read_table, run_study, table_without_costs
from astrobee_lab.study.spec import StudyError, load_study

pytest.importorskip("pybullet")

Q = [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]
# 2 controllers x 2 seeds, rigid bag, a 0.5 m hop in Node 2 with the astrobee realism knobs:
# about a second of CPU per flight
SMALL = {
    "name": "small",
    "controllers": {"pd": {"controller": "pd"},
                    "mpc_a": {"controller": "mpc", "params": {"model": "reduced", "samples": 16}}},
    "base": {"scenario": {"name": "hop", "flight_mode": "nominal",
                          "robots": [{"name": "", "position": [10.95, 0.4, 4.84], "orientation": Q}],
                          "bag": {"model": "rigid", "variant": "front", "mass": 10.0},
                          "goal": {"position": [10.95, -0.1, 4.84], "orientation": Q}},
             "realism": "astrobee"},
    "seeds": 2,
    "grid": {"controller": ["pd", "mpc_a"]},
}


def write(tmp_path: Path, data: dict, name: str = "small.yaml") -> Path:
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data, sort_keys=False))
    return p


def test_the_study_expands_to_the_grid_with_stable_keys(tmp_path):
    s = load_study(write(tmp_path, SMALL))
    assert [(f.label, f.spec["seed"]) for f in s.flights] == [("pd", 0), ("pd", 1),
                                                              ("mpc_a", 0), ("mpc_a", 1)]
    assert len({f.key for f in s.flights}) == 4
    assert [f.key for f in load_study(write(tmp_path, SMALL, "again.yaml")).flights] == \
        [f.key for f in s.flights]


def test_a_settle_budget_reaches_the_flights_task_and_leaves_other_keys_alone(tmp_path):
    """settle_budget (a flight key) is the Task's time after the plan's end; flights that do
    not set it keep their keys (a study gains a long-settle block without re-flying the rest)."""
    from astrobee_lab.study.spec import task_keywords
    plain = load_study(write(tmp_path, SMALL))
    longer = dict(SMALL, blocks=[{"name": "plain", "grid": {"controller": ["pd"]}},
                                 {"name": "long", "set": {"settle_budget": 90},
                                  "grid": {"controller": ["pd"]}}])
    longer.pop("grid")
    s = load_study(write(tmp_path, longer, "long.yaml"))
    by_block = {b: [f for f in s.flights if f.block == b] for b in ("plain", "long")}
    assert [f.key for f in by_block["plain"]] == [f.key for f in plain.flights if f.label == "pd"]
    assert {f.key for f in by_block["long"]}.isdisjoint(f.key for f in plain.flights)
    assert [task_keywords(f.spec) for f in by_block["long"]] == [{"settle_budget": 90.0}] * 2
    assert [task_keywords(f.spec) for f in by_block["plain"]] == [{}, {}]


def test_serial_and_pool_give_the_same_table(tmp_path):
    path = write(tmp_path, SMALL)
    a = run_study(path, tmp_path / "serial", workers=1, progress=False)
    b = run_study(path, tmp_path / "pool", workers=2, progress=False)
    assert a.flown == b.flown == 4 and a.errors == b.errors == 0
    ta, tb = read_table(a.table), read_table(b.table)
    assert [r["label"] for r in ta] == ["pd", "pd", "mpc_a", "mpc_a"]
    assert all(r["success"] is True for r in ta if r["label"] == "pd"), [r["cause"] for r in ta]
    assert all(r["status"] == "ok" and r["seed"] in (0, 1) for r in ta)
    assert table_without_costs(ta) == table_without_costs(tb)
    report = (tmp_path / "serial" / "report.md").read_text()
    assert "| pd | 2 | 100% (2/2) |" in report and "| mpc_a | 2 |" in report
    assert (tmp_path / "serial" / "plots" / "clearance_block0.png").is_file()
    again = run_study(path, tmp_path / "serial", workers=1, progress=False)
    assert again.flown == 0 and again.resumed == 4


def test_a_killed_study_resumes_and_never_flies_a_finished_flight_twice(tmp_path):
    data = dict(SMALL, seeds=3)
    path = write(tmp_path, data)
    out = tmp_path / "study"
    flights = out / "flights"
    proc = subprocess.Popen([sys.executable, "-m", "astrobee_lab.study.cli", "run", str(path),
                             "--out", str(out), "--workers", "2", "--quiet"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if flights.is_dir() and any(flights.glob("*.json")):
                break
            time.sleep(0.05)
        assert proc.poll() is None, "the study ended before it could be killed"
        os.killpg(proc.pid, signal.SIGKILL)       # the runner and its pool workers
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    deadline = time.monotonic() + 10
    while group_alive(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not group_alive(proc.pid)              # nothing of the study left running
    before = {p.stem: json.loads(p.read_text()) for p in flights.glob("*.json")}
    assert 1 <= len(before) < 6
    run = run_study(path, out, workers=1, progress=False)
    assert run.resumed == len(before) and run.flown == 6 - len(before)
    after = {p.stem: json.loads(p.read_text()) for p in flights.glob("*.json")}
    assert set(after) == {f.key for f in load_study(path).flights}
    for key, rec in before.items():               # untouched: not flown again
        assert after[key] == rec
    assert len(read_table(run.table)) == 6


def group_alive(pgid: int) -> list[int]:
    """Live (not zombie) processes of a process group, from /proc."""
    alive = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        if int(fields[2]) == pgid and fields[0] != "Z":
            alive.append(int(d.name))
    return alive


BAD = [
    ("not: [valid", "not valid YAML"),
    ("[" * 3000 + "]" * 3000, "YAML nested deeper than 100 levels"),   # was a RecursionError
    ("{a: " * 3000 + "1" + "}" * 3000, "YAML nested deeper than 100 levels"),
    ({"name": "x", "grid": {"controller": ["pd"]}, "colour": 1}, "unknown key 'colour'"),
    ({"grid": {"controller": ["lqr"]}}, "unknown controller 'lqr'"),
    ({"controllers": {"a": {"controller": "lqr"}}, "grid": {"controller": ["a"]}},
     f"controller must be {registry.choices_text()}, got 'lqr'"),
    ({"base": {"scenario": "no_such_place"}, "grid": {"controller": ["pd"]}}, "no_such_place"),
    ({"base": {"realism": {"ekf_position_noise": -1}}, "grid": {"controller": ["pd"]}},
     "ekf_position_noise"),
    ({"grid": {"controller": "pd"}}, "must be a non-empty list"),
    ({"controllers": {"m": {"controller": "mpc", "params": {"samples": 0}}},
      "grid": {"controller": ["m"]}}, "samples must be a positive integer"),
    ({"base": {"controller": "pd"}, "grid": {"realism.disturbances.0.magnitude": [5]}},
     "is not in the list"),
    ({"seeds": -1, "grid": {"controller": ["pd"]}}, "seeds must be"),
    ({"base": {"settle_budget": -5}, "grid": {"controller": ["pd"]}}, "settle_budget must be > 0 s"),
    ({"grid": {"controller": ["pd"]}, "random": {"count": 2, "draw": {"bag_mass": {"normal": 1}}}},
     "uniform"),
]


@pytest.mark.parametrize("content,needle", BAD)
def test_bad_study_files_are_one_line_errors(tmp_path, capsys, content, needle):
    p = tmp_path / "bad.yaml"
    p.write_text(content if isinstance(content, str) else yaml.safe_dump(content))
    with pytest.raises(StudyError):
        load_study(p)
    assert study_cli.main(["run", str(p), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("astrobee study: study "), err
    assert needle in err, err
    assert not (tmp_path / "out").exists()


def test_a_missing_file_and_bad_workers_are_one_line_errors(tmp_path, capsys):
    assert study_cli.main(["run", str(tmp_path / "none.yaml")]) == 1
    assert study_cli.main(["run", str(write(tmp_path, SMALL)), "--workers", "0"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err[0].endswith("no such file") and "--workers must be >= 1" in err[1]


def test_ray_gives_the_same_table(tmp_path):
    import ray          # in the test extra: the distributed path runs, never skips
    path = write(tmp_path, SMALL)
    a = run_study(path, tmp_path / "serial", workers=1, progress=False)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        b = run_study(path, tmp_path / "ray", ray="local", progress=False)
    finally:
        ray.shutdown()
    assert b.flown == 4 and b.errors == 0
    assert table_without_costs(read_table(a.table)) == table_without_costs(read_table(b.table))


@pytest.mark.graph
@pytest.mark.slow
def test_a_row_reflown_through_the_graph_matches_its_study_row(tmp_path):
    from astrobee_lab.study.reflow import reflow
    data = dict(SMALL, seeds=[1], grid={"controller": ["pd"]})
    run = run_study(write(tmp_path, data), tmp_path / "study", workers=1, progress=False)
    assert run.flown == 1
    res = reflow(tmp_path / "study", "0", timeout=240)
    assert res.launch_rc == 0, (res.run_dir / "launch.log").read_text()[-2000:]
    assert res.agrees, res.text()
    assert res.leg["scenario"].startswith("study_") and res.leg["success"] is True
    # the same seed reached the simulator: the realism knobs are in the graph's summary
    assert (res.run_dir / "bag").is_dir() and (res.run_dir / "reflow.json").is_file()


# ---- the report (no flights: rows made up for a swept study with labels) --------------------
SWEPT = dict(SMALL, seeds=3, labels={"realism.disturbances.0.magnitude": "bump on the bag (N)"},
             grid={"controller": ["pd", "mpc_a"], "realism.disturbances.0.magnitude": [2.0, 8.0]})
SWEPT["base"] = dict(SMALL["base"], realism={"preset": "astrobee", "disturbances": [
    {"target": "bag", "magnitude": 5.0, "duration": 0.2, "time": 1.0}]})


def _made_up_rows(study) -> list[dict]:
    """One row per flight: pd succeeds on every seed at 2 N and on seed 0 at 8 N; mpc_a on
    seeds 0 and 1 at both."""
    rows = []
    for f in study.flights:
        mag, seed = f.swept["realism.disturbances.0.magnitude"], f.spec["seed"]
        ok = (seed in (0, 1)) if f.label == "mpc_a" else (mag == 2.0 or seed == 0)
        rows.append({"index": f.index, "key": f.key, "block": f.block, "label": f.label,
                     "realism.disturbances.0.magnitude": mag, "seed": seed, "status": "ok",
                     "success": ok, "cause": "goal reached" if ok else "final position error",
                     "min_bag_clearance": 0.1 + 0.01 * seed, "contacts": 0, "wall_time": 1.0})
    return rows


def test_a_controller_failing_every_seed_is_plotted(tmp_path):
    """0 of 3 at a point: Wilson's lower end is the rate up to rounding (-5.6e-17 below it),
    which matplotlib refused as a negative error bar and the whole report failed."""
    from astrobee_lab.study.report import write_report
    from astrobee_lab.study.stats import wilson
    assert 0.0 - wilson(0, 3)[0] < 0.0                    # the rounding this guards against
    study = load_study(write(tmp_path, SWEPT))
    rows = [dict(r, success=False) if r["label"] == "mpc_a" else r
            for r in _made_up_rows(study)]
    md = write_report(study, rows, tmp_path).read_text()
    assert "| 2.0 | mpc_a | 3 | 0% (0/3) |" in md
    assert list((tmp_path / "plots").glob("success_vs_*.png"))


def test_the_report_states_intervals_pairs_and_is_one_html_page(tmp_path):
    from html.parser import HTMLParser

    from astrobee_lab.study.report import write_report
    from astrobee_lab.study.stats import paired, wilson
    study = load_study(write(tmp_path, SWEPT))
    md = write_report(study, _made_up_rows(study), tmp_path).read_text()
    lo, hi = wilson(3, 3)
    assert (lo, hi) == (pytest.approx(3 / (3 + 1.959964 ** 2)), 1.0)   # 3/3: 44-100%
    assert "| 2.0 | pd | 3 | 100% (3/3) | 44%-100% |" in md
    assert "\n| bump on the bag (N) | controller | n | success | success 95% interval |" in md
    # paired seeds at 8 N: pd only seed 0, mpc_a seeds 0 and 1: one discordant seed (1)
    assert paired("pd", "mpc_a", {0: True, 1: False, 2: False},
                  {0: True, 1: True, 2: False}).p_value == 1.0
    assert "| 8.0 | pd vs mpc_a | 3 | 1 | 0 (pd) | 1 (mpc_a) | 1 | 1 |" in md
    assert paired("a", "b", {s: True for s in range(6)}, {s: False for s in range(6)}
                  ).p_value == pytest.approx(2 / 64)         # 6 discordant seeds, one way

    class Page(HTMLParser):
        def __init__(self):
            super().__init__()
            self.tables, self.images, self.heads, self.xlinks = 0, [], [], []

        def handle_starttag(self, tag, attrs):
            a = dict(attrs)
            if tag == "table":
                self.tables += 1
            elif tag == "img":
                self.images.append(a.get("src", ""))
            elif tag == "link" or (tag == "script" and "src" in a) or "href" in a:
                self.xlinks.append(tag)

    page = Page()
    page.feed((tmp_path / "report.html").read_text())
    tables = sum(1 for ln in md.splitlines() if ln.startswith("|---"))
    assert page.tables == tables == 2                         # the block's table and its pairs
    pngs = sorted((tmp_path / "plots").glob("*.png"))
    assert len(pngs) == 2 and len(page.images) == md.count("![") == 2
    import base64
    assert all(src.startswith("data:image/png;base64,") for src in page.images)
    assert sorted(base64.b64decode(s.split(",", 1)[1]) for s in page.images) == \
        sorted(p.read_bytes() for p in pngs)
    assert not page.xlinks                                    # nothing fetched from elsewhere


def test_a_huge_grid_is_refused_before_anything_is_built(tmp_path, capsys):
    """99 x 1000 x 10 flights: the limit is checked from the sizes (it took 89 s and 3.9 GB
    when checked after building them)."""
    import tracemalloc
    data = dict(SMALL, seeds=list(range(10)),
                grid={"controller": ["pd"] * 99, "bag_mass": [5.0 + i * 0.001 for i in range(1000)]})
    p = tmp_path / "huge.yaml"
    p.write_text(yaml.safe_dump(data))
    tracemalloc.start()
    with pytest.raises(StudyError, match="more than 100000 flights"):
        load_study(p)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 50e6          # bytes: nothing built (a flight spec is ~4 KB)


@pytest.mark.parametrize("path", sorted((Path(__file__).resolve().parents[2] / "studies")
                                        .glob("*.yaml")), ids=lambda p: p.stem)
def test_every_study_file_loads(path):
    """Each study file of studies/ parses and names flights (a study written down before its
    flights must still be the one they were flown from)."""
    study = load_study(path)
    assert study.flights and study.name == path.stem
