"""The oracle as a study's upper bound: per condition, how many of the flown seeds the oracle
(astrobee_lab.oracle: offline optimal control of the reduced pair model with the bump known in
advance) finds feasible, and each controller's success on those seeds.

A study file names the oracle's results with `oracle: studies/results/oracle` (every block whose
flights carry a bump on the bag) or `oracle: {results: studies/results/oracle, blocks: [bump]}`
(those blocks only: the oracle solves one problem, the strap grasp on Node 2 -> JEM, so a clamp
block is left out). Rows are matched by (bump magnitude, seed); a seed the oracle has not solved
(yet) is counted as "not solved", never as feasible.
"""
from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any


def oracle_setting(source: dict) -> tuple[str, list[str] | None] | None:
    """(results directory as written, blocks or None for every block) of a study's `oracle:`
    (None without one). The shape was checked when the study was read (spec.parse_study)."""
    raw = source.get("oracle")
    if raw is None:
        return None
    if isinstance(raw, str):
        return raw, None
    return str(raw["results"]), (list(raw["blocks"]) if raw.get("blocks") is not None else None)


def check_setting(raw: Any) -> str | None:
    """Why a study's `oracle:` value is malformed (None when it is fine)."""
    if isinstance(raw, str) and raw:
        return None
    if not isinstance(raw, dict) or set(raw) - {"results", "blocks"} \
            or not isinstance(raw.get("results"), str):
        return ("oracle must be a results directory or {results: DIR, blocks: [names]}, got "
                f"{raw!r}")
    blocks = raw.get("blocks")
    if blocks is not None and not (isinstance(blocks, list)
                                   and all(isinstance(b, str) for b in blocks)):
        return f"oracle: blocks must be a list of block names, got {blocks!r}"
    return None


def resolve_dir(results: str) -> Path | None:
    """The results directory: absolute, or relative to the working directory, else to the
    repository (config/'s parent); None when neither exists."""
    p = Path(results)
    if p.is_absolute():
        return p if p.is_dir() else None
    if p.is_dir():
        return p
    from astrobee import config
    q = Path(config.config_dir()).parent / p
    return q if q.is_dir() else None


def load(results: str) -> tuple[dict[tuple[float, int], bool] | None, str]:
    """(the oracle's answers by (magnitude, seed), or None; a sentence on where they came
    from or why there are none)."""
    folder = resolve_dir(results)
    if folder is None:
        return None, f"oracle results not found at {results}"
    from astrobee_lab.oracle import load_feasibility
    try:
        answers = load_feasibility(folder)
    except (OSError, ValueError) as exc:
        return None, f"oracle results at {results} unreadable: {exc}"
    return answers, f"oracle results: {results} ({len(answers)} solved rows)"


def bag_bump(spec: dict) -> float | None:
    """The magnitude (N) of a flight's first bump on the bag; None without one."""
    realism = spec.get("realism")
    if not isinstance(realism, dict):
        return None
    for d in realism.get("disturbances") or []:
        if isinstance(d, dict) and d.get("target", "bag") == "bag" and d.get("magnitude"):
            return float(d["magnitude"])
    return None


def _order(v: Any) -> tuple:
    try:
        return (0, float(v), "")
    except (TypeError, ValueError):
        return (1, 0.0, str(v))


def oracle_rows(rows: list[dict], swept: list[str], specs: dict[str, dict],
                answers: dict[tuple[float, int], bool], names: dict[str, str] | None = None
                ) -> tuple[list[str], list[list[str]]] | None:
    """(headers, cells): one line per condition (the swept values but the controller): the
    oracle's count over the seeds flown and, per controller, its success on the oracle-feasible
    seeds. `specs`: flight key -> spec (for the bump magnitude). None when no row has a bump."""
    names = names or {}
    labels: list[str] = list(dict.fromkeys(r["label"] for r in rows))
    cond: dict[tuple, dict[str, dict[int, tuple[bool, float]]]] = defaultdict(lambda: defaultdict(dict))
    for r in rows:
        spec = specs.get(r.get("key"))
        mag = bag_bump(spec) if spec else None
        seed = r.get("seed")
        if mag is None or not isinstance(seed, int) or isinstance(seed, bool):
            continue
        cond[tuple(r.get(c) for c in swept)][r["label"]][seed] = (r.get("success") is True, mag)
    if not cond:
        return None
    out = []
    for values in sorted(cond, key=lambda k: tuple(_order(v) for v in k)):
        by = cond[values]
        seeds = {s: m for runs in by.values() for s, (_, m) in runs.items()}
        verdict = {s: answers.get((m, s)) for s, m in seeds.items()}
        feasible = {s for s, v in verdict.items() if v is True}
        infeasible = sum(v is False for v in verdict.values())
        unsolved = sum(v is None for v in verdict.values())
        cells = [*(str(v) for v in values),
                 f"{len(feasible)} of {len(seeds)}" + (f" ({infeasible} infeasible)" if infeasible
                                                      else "")
                 + (f" ({unsolved} not solved)" if unsolved else "")]
        for lab in labels:
            runs = by.get(lab, {})
            on = [runs[s][0] for s in feasible if s in runs]
            cells.append(f"{sum(on)} of {len(on)}" if on else "-")
        out.append(cells)
    heads = [*(names.get(c, c) for c in swept), "oracle: feasible seeds of those flown",
             *(f"{lab}: succeeds on the oracle-feasible seeds" for lab in labels)]
    return heads, out
