"""astrobee_lab.study's report statistics beyond success rates: Wilcoxon's signed-rank test on
paired continuous metrics, the study's `pairs`, and the oracle as the bound (its answers read
by (bump, seed), unsolved seeds said so). Made-up rows: nothing is flown."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from astrobee_lab.study.report import write_report
from astrobee_lab.study.spec import StudyError, parse_study
from astrobee_lab.study.stats import signed_rank

Q = [0.0, 0.0, -0.7071067811865476, 0.7071067811865476]
STUDY = {
    "name": "bound",
    "controllers": {"pd": {"controller": "pd"}, "pair": {"controller": "pair"},
                    "mpc_a": {"controller": "mpc", "params": {"model": "reduced"}}},
    "base": {"scenario": {"name": "hop", "flight_mode": "nominal",
                          "robots": [{"name": "", "position": [10.95, 0.4, 4.84], "orientation": Q}],
                          "bag": {"model": "rigid", "variant": "front", "mass": 10.0},
                          "goal": {"position": [10.95, -0.1, 4.84], "orientation": Q}},
             "realism": {"disturbances": [{"target": "bag", "magnitude": 5.0, "duration": 0.2,
                                           "t_min": 10.0, "t_max": 30.0}]}},
    "seeds": 4,
    "pairs": [["pd", "pair"], ["pd", "mpc_a"]],
    "blocks": [{"name": "bump", "grid": {"controller": ["pd", "pair", "mpc_a"],
                                         "realism.disturbances.0.magnitude": [5.0, 10.0]}},
               {"name": "still", "set": {"realism": "off"}, "grid": {"controller": ["pd"]}}],
}


def _rows(study) -> list[dict]:
    """pd succeeds on seeds 0-1, pair on 0-2, mpc_a on none; pair's bag clearance 5 cm more
    than pd's on every seed, mpc_a's time to rest unknown (never at rest)."""
    rows = []
    for f in study.flights:
        seed, lab = f.spec["seed"], f.label
        ok = seed < {"pd": 2, "pair": 3, "mpc_a": 0}[lab]
        rows.append({"index": f.index, "key": f.key, "block": f.block, "label": lab,
                     **f.swept, "seed": seed, "status": "ok", "success": ok, "cause": "x",
                     "min_bag_clearance": 0.1 + 0.01 * seed + (0.05 if lab == "pair" else 0.0),
                     "time_to_rest": float("nan") if lab == "mpc_a" else 40.0 + seed,
                     "contacts": 0})
    return rows


def test_signed_rank_is_scipys_wilcoxon_on_the_paired_differences():
    from scipy.stats import wilcoxon
    a = {s: float(s) for s in range(8)}
    b = {s: s + 0.1 * (s - 2) ** 2 - 0.05 for s in range(8)}
    b[9] = 1.0                                                 # only one side: not paired
    got = signed_rank(a, b)
    d = [b[s] - a[s] for s in range(8)]
    assert got.n == 8 and got.p_value == pytest.approx(wilcoxon(d).pvalue)
    assert got.median_diff == pytest.approx(sorted(d)[3] / 2 + sorted(d)[4] / 2)
    assert signed_rank({0: 1.0, 1: 2.0}, {0: 1.0, 1: 2.0}).p_value == 1.0
    assert signed_rank({0: float("nan")}, {0: 1.0}) is None


def test_the_report_pairs_the_continuous_metrics_and_bounds_by_the_oracle(tmp_path):
    oracle = tmp_path / "oracle"
    oracle.mkdir()
    # 5 N: seeds 0-2 feasible, 3 not solved; 10 N: seed 0 infeasible, 1-3 feasible
    (oracle / "feasibility.csv").write_text(
        "magnitude,seed,feasible\n5.0,0,True\n5.0,1,True\n10.0,0,False\n10.0,1,True\n")
    (oracle / "feasibility_b.csv").write_text(
        "magnitude,seed,feasible\n5.0,2,True\n10.0,2,True\n10.0,3,True\n")
    (oracle / "feasibility_margin0.csv").write_text("magnitude,seed,feasible\n5.0,3,False\n")
    study = parse_study(dict(STUDY, oracle={"results": str(oracle), "blocks": ["bump"]}))
    md = write_report(study, _rows(study), tmp_path).read_text()
    assert "oracle: feasible seeds of those flown | pd: succeeds on the oracle-feasible seeds" in md
    assert "| 5.0 | 3 of 4 (1 not solved) | 2 of 3 | 3 of 3 | 0 of 3 |" in md
    assert "| 10.0 | 3 of 4 (1 infeasible) | 1 of 3 | 2 of 3 | 0 of 3 |" in md
    # the study's pairs only (no pair vs mpc_a); pair's clearance +5 cm on 4 of 4 seeds
    assert "pair vs mpc_a" not in md and "| 5.0 | pd vs mpc_a | 4 |" in md
    assert "| 5.0 | pd vs pair | 4 | 2 | 0 (pd) | 1 (pair) | 1 | 1 | +0.050 (p 0.12, n 4) |" in md
    assert "| +0.0 (p 1, n 4) |" in md and "| - |" in md      # time to rest: equal; mpc_a none
    assert "min bag clearance m: median paired diff, second - first (Wilcoxon p, n)" in md
    assert "still: against the oracle" not in md                # not an oracle block
    assert "<h3>bump: against the oracle</h3>" in (tmp_path / "report.html").read_text()


def test_an_oracle_without_results_is_said_and_bad_settings_are_one_line(tmp_path):
    study = parse_study(dict(STUDY, oracle=str(tmp_path / "none")))
    md = write_report(study, _rows(study), tmp_path).read_text()
    assert f"oracle results not found at {tmp_path / 'none'}" in md
    assert "against the oracle" not in md
    for bad, needle in (({"pairs": [["pd", "nope"]]}, "pairs must be a list of [label, label]"),
                        ({"pairs": "pd"}, "pairs must be"),
                        ({"oracle": {"dir": "x"}}, "oracle must be a results directory"),
                        ({"oracle": {"results": "x", "blocks": "bump"}}, "blocks must be a list")):
        with pytest.raises(StudyError, match="^study: ") as e:
            parse_study(dict(STUDY, **bad))
        assert needle in str(e.value) and "\n" not in str(e.value)


def test_the_pair_control_study_file_reads():
    root = Path(__file__).resolve().parents[2]
    path = root / "studies" / "pair_control_study.yaml"
    if not path.is_file():
        pytest.skip("no pair_control_study.yaml yet")
    from astrobee_lab.study.spec import load_study
    study = load_study(path)
    seeds = {f.spec["seed"] for f in study.flights}
    assert len(seeds) >= 20
    assert yaml.safe_load(path.read_text())["oracle"]
