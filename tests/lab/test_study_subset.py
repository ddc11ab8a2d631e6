"""`astrobee study run FILE --only KEY=V1,V2`: a subset of the study's flights with the same
keys (so the whole study resumes from them), bad filters one line each. Nothing is flown."""
from __future__ import annotations

from pathlib import Path

import pytest

from astrobee_lab.study import cli as study_cli
from astrobee_lab.study.spec import StudyError, load_study
from astrobee_lab.study.subset import parse_only, select

STUDY = Path(__file__).resolve().parents[2] / "studies" / "pair_control_study.yaml"


def test_a_subset_keeps_the_keys_of_the_whole_study():
    whole = load_study(STUDY)
    sub = select(whole, parse_only(["controller=pd,wmpc", "block=bump",
                                    "realism.disturbances.0.magnitude=5,10.0"]))
    assert len(sub.flights) == 2 * 2 * len({f.spec["seed"] for f in whole.flights})
    assert {f.label for f in sub.flights} == {"pd", "wmpc"}
    assert {f.swept["realism.disturbances.0.magnitude"] for f in sub.flights} == {5.0, 10.0}
    assert {f.key for f in sub.flights} <= set(whole.unique)
    assert [f.index for f in sub.flights] == list(range(len(sub.flights)))
    assert "subset: controller in pd, wmpc" in sub.description
    assert len(select(whole, parse_only(["seed=0"])).flights) * 20 == len(whole.flights)


@pytest.mark.parametrize("only, needle", [
    (["controller"], "--only takes KEY=VALUE"),
    (["nope=1"], "--only nope: not a controller, block, seed or swept parameter"),
    (["controller=nobody"], "--only leaves no flight"),
])
def test_bad_filters_are_one_line(only, needle, capsys):
    with pytest.raises(StudyError, match=needle):
        select(load_study(STUDY), parse_only(only))
    argv = ["run", str(STUDY), "--list"] + [a for o in only for a in ("--only", o)]
    assert study_cli.main(argv) == 1
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1


def test_a_subset_report_says_so_and_reads_the_oracle(tmp_path):
    import json

    import yaml
    whole = load_study(STUDY)
    (tmp_path / "flights").mkdir()
    (tmp_path / "study.yaml").write_text(yaml.safe_dump(whole.source, sort_keys=False))
    picked = [f for f in whole.flights if f.block == "bump" and f.spec["seed"] == 0
              and f.label in ("pd", "wmpc") and f.swept["realism.disturbances.0.magnitude"] == 5.0]
    for f, ok in zip(picked, (False, True)):
        (tmp_path / "flights" / f"{f.key}.json").write_text(json.dumps(
            {"key": f.key, "spec": f.spec, "status": "ok",
             "row": {"seed": 0, "success": ok, "cause": "x", "min_bag_clearance": 0.2,
                     "contacts": 0}}))
    argv = ["report", str(tmp_path), "--only", "controller=pd,wmpc", "--only", "block=bump"]
    assert study_cli.main(argv) == 0
    md = (tmp_path / "report.md").read_text()
    assert f"(subset: controller in pd, wmpc; block in bump; 160 of {len(whole.flights)} rows)" in md
    assert "2 of 160 rows flown" in md
    # the repository's oracle answers for seed 0 at 5 N (solved: feasible)
    assert "\n| 1 of 1 | 0 of 1 | 1 of 1 |" in md
