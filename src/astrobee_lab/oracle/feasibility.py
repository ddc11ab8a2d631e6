"""The oracle study's answers read back: (bump magnitude, seed) -> feasible, for other studies
to pair their rows with (studies/oracle_feasibility.py writes them).

Which files count: the study writes `feasibility.csv` and, when split across processes,
`feasibility_<letter>.csv` (feasibility_b.csv, ...): all of those are one model (the `pair: fem`
parameters of config/reduced_models.yaml, the bag's corners 5 cm off the walls). Any other
`feasibility_<name>.csv` is a variant of the problem (feasibility_margin0.csv: the bag's corners
allowed on the walls, an earlier identification; feasibility_bumped.csv: the `pair: fem_bumped` model
fitted on bumped flights) and is not read.
"""
from __future__ import annotations

import csv
import re
from pathlib import Path

STUDY_FILE = re.compile(r"^feasibility(_[a-z])?\.csv$")


def study_files(directory: str | Path) -> list[Path]:
    """The CSVs of the study's model in `directory` (module docstring), sorted by name."""
    return sorted(p for p in Path(directory).iterdir() if STUDY_FILE.match(p.name))


def load_feasibility(directory: str | Path) -> dict[tuple[float, int], bool]:
    """{(magnitude in N, seed): the oracle found the row feasible} over the study's files in
    `directory`. A row present in two files must give the same answer (else ValueError)."""
    out: dict[tuple[float, int], bool] = {}
    files = study_files(directory)
    if not files:
        raise FileNotFoundError(f"no oracle study CSV (feasibility.csv, feasibility_<letter>.csv) in {directory}")
    for path in files:
        with open(path, newline="") as f:
            for r in csv.DictReader(f):
                key = (float(r["magnitude"]), int(r["seed"]))
                value = r["feasible"].strip() == "True"
                if key in out and out[key] != value:
                    raise ValueError(f"{path.name}: row {key} disagrees with an earlier file")
                out[key] = value
    return out
