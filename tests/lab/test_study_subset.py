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
