"""load_feasibility reads the oracle study's CSVs (feasibility.csv, feasibility_<letter>.csv),
skips variants of the problem (feasibility_margin0.csv) and refuses files that disagree."""
from __future__ import annotations

from pathlib import Path

import pytest

from astrobee_lab.oracle import load_feasibility

HEADER = "magnitude,seed,bump_time,fx,fy,fz,feasible,status,solve_time,nodes,box,goal,attitude,rest_speed,rest_omega\n"


def _write(path: Path, rows: list[tuple[float, int, bool]]) -> None:
    path.write_text(HEADER + "".join(f"{m},{s},20.0,1,0,0,{ok},solved,30.0,97,0.0,0.16,0.28,0.008,0.016\n"
                                     for m, s, ok in rows))


def test_reads_the_study_files_and_skips_variants(tmp_path):
    _write(tmp_path / "feasibility.csv", [(2.5, 0, True), (10.0, 0, False)])
    _write(tmp_path / "feasibility_b.csv", [(5.0, 10, True), (2.5, 0, True)])
    _write(tmp_path / "feasibility_margin0.csv", [(7.5, 3, True), (10.0, 0, True)])
    (tmp_path / "flown.csv").write_text("magnitude,seed\n5.0,0\n")
    got = load_feasibility(tmp_path)
    assert got == {(2.5, 0): True, (10.0, 0): False, (5.0, 10): True}


def test_disagreeing_files_and_an_empty_directory_are_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_feasibility(tmp_path)
    _write(tmp_path / "feasibility.csv", [(5.0, 1, True)])
    _write(tmp_path / "feasibility_c.csv", [(5.0, 1, False)])
    with pytest.raises(ValueError, match="disagrees"):
        load_feasibility(tmp_path)


def test_the_committed_study_rows_load():
    root = Path(__file__).resolve().parents[2] / "studies" / "results" / "oracle"
    got = load_feasibility(root)
    assert len(got) >= 47 and {m for m, _ in got} == {2.5, 5.0, 7.5, 10.0}
    assert got[(7.5, 2)] is False and got[(5.0, 0)] is True


@pytest.mark.parametrize("argv, words", [
    (["--margin", "0"], "--margin must be in (0, 1], got 0.0"),
    (["--margin", "1.5"], "--margin must be in (0, 1], got 1.5"),
    (["--seed-list", "x"], "argument --seed-list: invalid int value: 'x'"),
])
def test_bad_arguments_are_one_line(study_script, monkeypatch, capsys, argv, words):
    mod = study_script("oracle_feasibility")
    monkeypatch.setattr("sys.argv", ["oracle_feasibility.py", *argv])
    with pytest.raises(SystemExit) as e:
        mod.main()
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert words in err[-1]
