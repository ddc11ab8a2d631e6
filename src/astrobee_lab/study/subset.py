"""A subset of a study's flights (`astrobee study run FILE --only controller=pd,wmpc --only
realism.disturbances.0.magnitude=5,10`): the same flights with the same keys, so a subset flown
into a study folder is resumed, not flown again, by the whole study later."""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

from .spec import Study, StudyError

# what a filter may name beside the swept parameters
FIELDS = ("controller", "block", "seed")


def parse_only(items: list[str]) -> dict[str, list[str]]:
    """KEY=V1,V2 items -> {KEY: [values]} (a key given twice: its values joined)."""
    out: dict[str, list[str]] = {}
    for item in items:
        key, sep, values = item.partition("=")
        vals = [v.strip() for v in values.split(",") if v.strip()]
        if not sep or not key.strip() or not vals:
            raise StudyError(f"--only takes KEY=VALUE[,VALUE...], got {item!r}")
        out.setdefault(key.strip(), []).extend(vals)
    return out


def _same(value: Any, wanted: str) -> bool:
    if str(value) == wanted:
        return True
    try:
        a, b = float(value), float(wanted)
    except (TypeError, ValueError):
        return False
    return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)


def select(study: Study, only: dict[str, list[str]]) -> Study:
    """The study with only the flights every filter matches (controller label, block, seed or
    a swept parameter; StudyError for a key no flight has, or no flight left)."""
    if not only:
        return study
    known = set(FIELDS) | set(study.swept_columns)
    for key in only:
        if key not in known:
            raise StudyError(f"--only {key}: not a controller, block, seed or swept parameter of "
                             f"the study (swept: {', '.join(study.swept_columns) or 'none'})")

    def value(f, key: str) -> Any:
        return {"controller": f.label, "block": f.block, "seed": f.spec["seed"]}[key] \
            if key in FIELDS else f.swept.get(key)

    kept = [f for f in study.flights
            if all(any(_same(value(f, k), v) for v in vals) for k, vals in only.items())]
    if not kept:
        raise StudyError("--only leaves no flight of the study")
    text = "; ".join(f"{k} in {', '.join(v)}" for k, v in only.items())
    return replace(study, flights=[replace(f, index=i) for i, f in enumerate(kept)],
                   description=(study.description.strip() + f" (subset: {text}; "
                                f"{len(kept)} of {len(study.flights)} rows)").strip())
