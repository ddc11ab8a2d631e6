"""studies/bump_time_split.py: flights split by their seed's bump time, counted per magnitude and
controller; the oracle's feasibility split by its own bump_time column; a bad path one line."""
import csv

import pytest

from astrobee_lab.oracle.solve import bump_of_seed


def row(seed: int, label: str, mag: float, ok: bool) -> dict:
    return {"seed": str(seed), "label": label, "realism.disturbances.0.magnitude": str(mag),
            "success": str(ok), "status": "ok"}


def test_split_counts_by_bump_time(study_script):
    mod = study_script("bump_time_split")
    times = {1: 12.0, 2: 25.0, 3: 23.0}.__getitem__
    rows = [row(1, "pd", 5.0, True), row(2, "pd", 5.0, False), row(3, "pd", 5.0, True),
            row(1, "gov", 5.0, True), row(1, "pd", 0.0, True),          # no bump: left out
            {**row(2, "gov", 5.0, True), "status": "error"},            # not flown: left out
            {**row(2, "gov", 5.0, True), "block": "budget90"}]          # skipped below
    c = mod.split_counts(rows, 23.0, times, skip_blocks=("budget90",))
    assert c == {(5.0, "pd"): {"early": [1, 1], "late": [1, 2]},
                 (5.0, "gov"): {"early": [1, 1], "late": [0, 0]}}
    assert mod.fisher_p([10, 10], [0, 10]) < 0.001 and mod.fisher_p([5, 10], [5, 10]) == 1.0


def test_bump_time_is_the_simulators_draw_whatever_the_magnitude(study_script):
    mod = study_script("bump_time_split")
    assert mod.bump_time(276) == pytest.approx(bump_of_seed(276, 7.5).time)
    assert 10.0 <= mod.bump_time(276) <= 30.0


def test_oracle_counts_and_the_table(study_script, tmp_path, capsys):
    mod = study_script("bump_time_split")
    oracle = [{"magnitude": "10.0", "bump_time": "27.9", "feasible": "True"},
              {"magnitude": "10.0", "bump_time": "10.3", "feasible": "False"}]
    assert mod.oracle_counts(oracle, 23.0) == {10.0: {"early": [0, 1], "late": [1, 1]}}
    res = tmp_path / "results.csv"
    with open(res, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(row(0, "", 0, True)))
        w.writeheader()
        w.writerows([row(276, "pd", 10.0, False), row(260, "pd", 10.0, True)])
    orc = tmp_path / "oracle.csv"
    with open(orc, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(oracle[0]))
        w.writeheader()
        w.writerows(oracle)
    assert mod.main(["--results", str(res), "--oracle", str(orc), "--split", "23"]) == 0
    out = capsys.readouterr().out        # seed 260's bump comes at 12.9 s, 276's at 27.1 s
    assert "| 10 | pd | 1/1 (21-100%) | 0/1 (0-79%) | 1 |" in out, out
    assert "| 10 | oracle feasible (all its seeds) | 0/1 (0-79%) | 1/1 (21-100%) | |" in out, out
    assert mod.main(["--results", str(tmp_path / "missing.csv")]) == 2
    err = capsys.readouterr().err
    assert "cannot read" in err and err.count("\n") == 1
    assert mod.main(["--results", str(res), "--oracle", str(tmp_path / "none.csv")]) == 2
    err = capsys.readouterr().err
    assert "cannot read" in err and "none.csv" in err and err.count("\n") == 1
    assert mod.main(["--results", str(orc)]) == 2           # the oracle's CSV as results
    err = capsys.readouterr().err
    assert "not a study's results.csv" in err and err.count("\n") == 1
