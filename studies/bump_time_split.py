"""Split a study's bumped flights by when the bump came: success per controller before and after
a bump time, with the oracle's feasibility on the same split.

A seed's bump time is the simulator's own draw (astrobee_lab.oracle.solve.bump_of_seed), so the
split needs no column the study did not write. Example (the thirteenth session's table in
docs/results/pair_control_followup.md section 12):

    python studies/bump_time_split.py --results studies/results/unwind/results.csv \
        --oracle studies/results/oracle/feasibility_bumped.csv --split 20

Per magnitude and controller: successes / flights early and late with Wilson 95% intervals and
Fisher's exact p on the 2x2 (early/late x success/failure); per magnitude the oracle's feasible /
solved on each side.
"""
from __future__ import annotations

import argparse
import csv
import sys
from collections import defaultdict
from functools import lru_cache

from astrobee_lab.oracle.solve import bump_of_seed
from astrobee_lab.study.stats import wilson

MAG = "realism.disturbances.0.magnitude"
RESULT_COLUMNS = ("seed", "label", "success", MAG)
ORACLE_COLUMNS = ("magnitude", "bump_time", "feasible")


@lru_cache(maxsize=None)
def bump_time(seed: int) -> float:
    """The seed's bump time (s): the draw does not depend on the magnitude."""
    return bump_of_seed(seed, 1.0).time


def split_counts(rows: list[dict], split: float, times=bump_time,
                 skip_blocks: tuple = ()) -> dict:
    """(magnitude, label) -> {"early": [successes, n], "late": [...]} over bumped rows (but
    those of `skip_blocks`); a row is late when its seed's bump came at or after `split` s."""
    out: dict = defaultdict(lambda: {"early": [0, 0], "late": [0, 0]})
    for r in rows:
        if not r.get(MAG) or float(r[MAG]) <= 0 or r.get("status", "ok") != "ok" \
                or r.get("block") in skip_blocks:
            continue
        side = "late" if times(int(r["seed"])) >= split else "early"
        cell = out[(float(r[MAG]), r["label"])][side]
        cell[0] += str(r["success"]) == "True"
        cell[1] += 1
    return dict(out)


def oracle_counts(rows: list[dict], split: float) -> dict:
    """magnitude -> {"early": [feasible, solved], "late": [...]} from a feasibility CSV (its
    own bump_time column)."""
    out: dict = defaultdict(lambda: {"early": [0, 0], "late": [0, 0]})
    for r in rows:
        side = "late" if float(r["bump_time"]) >= split else "early"
        cell = out[float(r["magnitude"])][side]
        cell[0] += r["feasible"] == "True"
        cell[1] += 1
    return dict(out)


def fisher_p(a: list[int], b: list[int]) -> float:
    """Fisher's exact two-sided p for successes / n on two sides."""
    from scipy.stats import fisher_exact
    return float(fisher_exact([[a[0], a[1] - a[0]], [b[0], b[1] - b[0]]])[1])


def read_csv(path: str, columns: tuple) -> list[dict]:
    """A CSV's rows as dicts (OSError when it cannot be read, KeyError naming the first of
    `columns` it lacks)."""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = [c for c in columns if c not in (reader.fieldnames or ())]
        if missing:
            raise KeyError(missing[0])
        return list(reader)


def cell(c: list[int]) -> str:
    lo, hi = wilson(c[0], c[1])
    return f"{c[0]}/{c[1]} ({100 * lo:.0f}-{100 * hi:.0f}%)" if c[1] else "-"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("--results", nargs="+", required=True, help="study results.csv files")
    ap.add_argument("--oracle", help="an oracle feasibility CSV (studies/oracle_feasibility.py)")
    ap.add_argument("--split", type=float, default=20.0,
                    help="bump time (s) late starts at (default 20: the window's middle)")
    ap.add_argument("--skip-block", action="append", default=[],
                    help="leave this block's rows out (repeatable; e.g. a longer budget's)")
    a = ap.parse_args(argv)
    try:
        rows = [r for path in a.results for r in read_csv(path, RESULT_COLUMNS)]
        counts = split_counts(rows, a.split, skip_blocks=tuple(a.skip_block))
        oc = oracle_counts(read_csv(a.oracle, ORACLE_COLUMNS), a.split) if a.oracle else {}
    except OSError as e:
        print(f"bump_time_split: cannot read {e.filename}: {e.strerror}", file=sys.stderr)
        return 2
    except (KeyError, ValueError) as e:
        print(f"bump_time_split: not a study's results.csv or an oracle feasibility CSV "
              f"(column {e} missing or unreadable)", file=sys.stderr)
        return 2
    print(f"| bump (N) | controller | bump < {a.split:g} s | bump >= {a.split:g} s | Fisher p |")
    print("|---|---|---|---|---|")
    for (m, label), c in sorted(counts.items()):
        print(f"| {m:g} | {label} | {cell(c['early'])} | {cell(c['late'])} | "
              f"{fisher_p(c['early'], c['late']):.2g} |")
    for m, c in sorted(oc.items()):
        print(f"| {m:g} | oracle feasible (all its seeds) | {cell(c['early'])} | "
              f"{cell(c['late'])} | |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
