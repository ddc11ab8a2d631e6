"""A study file (YAML) read, validated and expanded into the list of flights it asks for.

    name: pd_vs_mpc                    # the study folder is runs/study_<name>/
    controllers:                       # labels -> a registered law (pd | mpc | ...), its params
      pd: {controller: pd}             #   (config/controllers.yaml's section under them) and
      mpc_a: {controller: mpc, params: {model: reduced}}      # safety (the CBF filter)
    base: {scenario: node2_to_jem_fem_bag, realism: astrobee} # every flight's parameters
    seeds: 5                           # 0..4, or a list
    time_limit: 90                     # optional, sim s (else the Task's: plan + settle + 10 s)
    labels: {realism.disturbances.0.magnitude: bump on the bag (N)}  # report axes (optional)
    pairs: [[pd, mpc_a]]               # paired comparisons in the report (default: every two)
    oracle: studies/results/oracle     # the oracle's answers per (bump, seed) as a bound (optional;
                                       #   or {results: DIR, blocks: [names]})
    metrics: [success, contacts, min_bag_clearance]   # columns kept in the table (default: all)
    blocks:                            # each block: set (fixed) x grid (product) x random draws
      - name: routes
        grid: {controller: [pd, mpc_a], scenario: [node2_to_jem_fem_bag, jem_to_node1]}
      - name: bumps
        set: {realism.disturbances: [{target: bag, magnitude: 5, duration: 0.2, time: 10}]}
        grid: {controller: [pd, mpc_a], realism.disturbances.0.magnitude: [5, 10, 20]}
        random: {count: 4, seed: 1, draw: {realism.bag_stiffness_scale: {uniform: [0.1, 1]}}}

A grid axis `case` takes a list of named parameter sets (`- {name: difficult, flight_mode:
difficult}`): conditions that differ in several parameters, shown by name in the table.
Blocks may share a name (their rows are reported together). Without `blocks`, a top-level `grid` / `random` / `set` is the one block. Flight parameters:
scenario (a name of config/scenarios or an inline scenario mapping), controller (a label),
safety, bag_model, bag_variant, bag_resolution, bag_mass, fem_solver, flight_mode, realism (a
preset name or a mapping of knobs), state_source, time_limit, settle_budget (s after the plan's
end to be at rest at the goal; the Task's 30 s else), params (controller parameters over the
label's), and dotted paths into the mappings (`realism.<knob>`, `params.<name>`,
`realism.disturbances.0.magnitude`). Every flight is keyed by a stable hash of what is flown
(the controller's definition, not its label), so a flight that two blocks share runs once.
Bad files raise StudyError with one line naming the file and the problem.
"""
from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from astrobee.overrides import OVERRIDE_KEYS, parse_overrides
from roszen import yamltext

TOP_KEYS = {"name", "description", "controllers", "base", "seeds", "time_limit", "metrics",
            "blocks", "grid", "random", "set", "notes", "labels", "pairs", "oracle"}
BLOCK_KEYS = {"name", "set", "grid", "random", "seeds", "description"}
# the scenario overrides a flight may set (astrobee.overrides; realism is kept apart in a spec)
OVERRIDES = tuple(k for k in OVERRIDE_KEYS if k not in ("realism", "robots"))
FLIGHT_KEYS = {"scenario", "controller", "safety", *OVERRIDES, "realism", "state_source",
               "time_limit", "settle_budget", "params"}
TASK_KEYS = ("time_limit", "settle_budget")     # a flight's Task keywords (sim s)
DOTTED_ROOTS = {"realism", "params", "scenario"}
DISTRIBUTIONS = ("uniform", "loguniform", "choice", "randint")
MAX_FLIGHTS = 100000


class StudyError(ValueError):
    """A bad study file (one line)."""


@dataclass(frozen=True)
class FlightSpec:
    """One flight of a study: what is flown (`spec`, hashed into `key`) and how it shows in
    the table (`label`: the controller's label, `block`, `swept`: the block's varied values)."""

    key: str
    spec: dict
    label: str
    block: str
    swept: dict = field(default_factory=dict)
    index: int = 0


@dataclass
class Study:
    """A study file expanded: its name, the flights in table order, the metrics kept."""

    name: str
    flights: list[FlightSpec]
    metrics: list[str] | None
    source: dict
    path: Path | None = None
    description: str = ""

    @property
    def unique(self) -> dict[str, FlightSpec]:
        """key -> the first flight of that key (what actually has to be flown)."""
        out: dict[str, FlightSpec] = {}
        for f in self.flights:
            out.setdefault(f.key, f)
        return out

    @property
    def swept_columns(self) -> list[str]:
        """The varied parameters of every block, in first-seen order."""
        cols: list[str] = []
        for f in self.flights:
            cols += [c for c in f.swept if c not in cols]
        return cols


def flight_key(spec: dict) -> str:
    """A stable hash of what a flight flies (16 hex digits)."""
    text = json.dumps(spec, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _plain(value: Any) -> Any:
    """YAML-safe plain data (numpy scalars to Python, tuples to lists)."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _set_path(target: dict, path: str, value: Any, where: str) -> None:
    """target[path] = value for a dotted path; a string realism becomes {preset: name} first,
    list indices are numbers."""
    parts = path.split(".")
    root = parts[0]
    if len(parts) == 1:
        target[root] = copy.deepcopy(value)
        return
    if root not in DOTTED_ROOTS:
        raise StudyError(f"{where}: {path!r}: only realism.*, params.* and scenario.* (an inline "
                         "scenario) take dotted paths")
    node = target.get(root)
    if root == "realism" and (node is None or isinstance(node, str)):
        node = {} if node in (None, "", "off") else {"preset": node}
        target[root] = node
    elif root == "params" and node is None:
        node = target[root] = {}
    elif root == "scenario" and not isinstance(node, dict):
        raise StudyError(f"{where}: {path!r} needs an inline scenario mapping, got scenario "
                         f"{node!r}")
    for i, part in enumerate(parts[1:-1], 1):
        key: Any = int(part) if isinstance(node, list) and part.isdigit() else part
        try:
            nxt = node[key]
        except (KeyError, IndexError, TypeError):
            if isinstance(node, dict) and not parts[i + 1].isdigit():
                nxt = node[key] = {}
            else:
                raise StudyError(f"{where}: {path!r}: {'.'.join(parts[:i + 1])!r} is not in "
                                 "the list or mapping (set it first, e.g. in base)") from None
        node = nxt
    last = parts[-1]
    if isinstance(node, list):
        if not last.isdigit() or int(last) >= len(node):
            raise StudyError(f"{where}: {path!r}: index {last!r} is not in the list")
        node[int(last)] = copy.deepcopy(value)
    elif isinstance(node, dict):
        node[last] = copy.deepcopy(value)
    else:
        raise StudyError(f"{where}: {path!r}: {'.'.join(parts[:-1])!r} is not a mapping")


def _check_keys(d: Any, allowed: set, where: str) -> dict:
    if d is None:
        return {}
    if not isinstance(d, dict):
        raise StudyError(f"{where} must be a mapping, got {d!r}")
    for k in d:
        root = str(k).split(".")[0]
        if root not in allowed:
            raise StudyError(f"{where}: unknown key {str(k)!r}; known: {', '.join(sorted(allowed))}")
    return d


def _seeds(value: Any, where: str) -> list[int]:
    if value is None:
        return [0]
    if isinstance(value, bool):
        raise StudyError(f"{where}: seeds must be a count or a list of integers >= 0, got {value!r}")
    if isinstance(value, int):
        if not 1 <= value <= 10000:
            raise StudyError(f"{where}: seeds must be a count 1..10000, got {value}")
        return list(range(value))
    if isinstance(value, list) and value and all(isinstance(s, int) and not isinstance(s, bool)
                                                 and s >= 0 for s in value):
        return list(value)
    raise StudyError(f"{where}: seeds must be a count or a list of integers >= 0, got {value!r}")


def _draw(rng: np.random.Generator, dist: Any, where: str) -> Any:
    if not isinstance(dist, dict) or len(dist) != 1 or next(iter(dist)) not in DISTRIBUTIONS:
        raise StudyError(f"{where} must be one of {{uniform|loguniform|randint: [lo, hi]}} or "
                         f"{{choice: [...]}}, got {dist!r}")
    kind, arg = next(iter(dist.items()))
    if kind == "choice":
        if not isinstance(arg, list) or not arg:
            raise StudyError(f"{where}: choice needs a non-empty list, got {arg!r}")
        return copy.deepcopy(arg[int(rng.integers(len(arg)))])
    if (not isinstance(arg, list) or len(arg) != 2
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in arg)
            or not arg[0] <= arg[1]):
        raise StudyError(f"{where}: {kind} needs [lo, hi] with lo <= hi, got {arg!r}")
    lo, hi = arg
    if kind == "randint":
        return int(rng.integers(int(lo), int(hi) + 1))
    if kind == "loguniform":
        if lo <= 0:
            raise StudyError(f"{where}: loguniform needs lo > 0, got {lo!r}")
        v = math.exp(rng.uniform(math.log(lo), math.log(hi)))
    else:
        v = float(rng.uniform(lo, hi))
    return float(f"{v:.6g}")     # short and stable: the value is part of the flight's key


def _controllers(raw: Any, where: str) -> dict[str, dict]:
    out: dict[str, dict] = {}
    from astrobee_control import registry
    if raw is None:
        raw = {k: {"controller": k} for k in registry.names()}
    if not isinstance(raw, dict) or not raw:
        raise StudyError(f"{where}: controllers must be a mapping label -> {{controller, params, "
                         f"safety}}, got {raw!r}")
    for label, d in raw.items():
        w = f"{where}: controller {label!r}"
        if isinstance(d, str):
            d = {"controller": d}
        _check_keys(d, {"controller", "params", "safety", "description"}, w)
        kind = d.get("controller", label)
        if kind not in registry.names():
            raise StudyError(f"{w}: controller must be {registry.choices_text()}, got {kind!r}")
        params = d.get("params") or {}
        if not isinstance(params, dict):
            raise StudyError(f"{w}: params must be a mapping, got {params!r}")
        safety = d.get("safety", False)
        if not isinstance(safety, bool):
            raise StudyError(f"{w}: safety must be true or false, got {safety!r}")
        out[str(label)] = {"controller": kind, "params": dict(params), "safety": safety}
    return out


def _check_params(kind: str, params: dict, where: str) -> None:
    """The controller's parameters as its registry entry checks them, without building it."""
    from astrobee_control import registry
    try:
        registry.get(kind).check_params(params)
    except ValueError as exc:
        raise StudyError(f"{where}: {exc}") from None


def resolve_flight(values: dict, controllers: dict[str, dict], where: str) -> tuple[dict, str]:
    """The spec of one flight (what is flown; hashed) and its controller label."""
    label = values.get("controller")
    if label is None:
        raise StudyError(f"{where}: no controller (give one in base, set or grid)")
    label = str(label)
    if label not in controllers:
        raise StudyError(f"{where}: unknown controller {label!r}; known: {', '.join(controllers)}")
    ctl = controllers[label]
    params = {**ctl["params"], **(values.get("params") or {})}
    if values.get("params") is not None and not isinstance(values.get("params"), dict):
        raise StudyError(f"{where}: params must be a mapping")
    kind = ctl["controller"]
    _check_params(kind, params, f"{where}: controller {label!r}")
    safety = values.get("safety", ctl["safety"])
    if not isinstance(safety, bool):
        raise StudyError(f"{where}: safety must be true or false, got {safety!r}")
    scenario = values.get("scenario", "node2_to_jem_bag")
    if not isinstance(scenario, (str, dict)):
        raise StudyError(f"{where}: scenario must be a name or an inline mapping, got {scenario!r}")
    realism = values.get("realism")
    if realism is not None and not isinstance(realism, (str, dict)):
        raise StudyError(f"{where}: realism must be a preset name or a mapping, got {realism!r}")
    state_source = values.get("state_source", "ekf")
    if state_source not in ("ekf", "truth"):
        raise StudyError(f"{where}: state_source must be ekf or truth, got {state_source!r}")
    spec: dict[str, Any] = {"scenario": scenario, "controller": kind, "params": params,
                            "safety": safety, "realism": realism, "state_source": state_source,
                            "overrides": {k: values[k] for k in OVERRIDES if values.get(k) is not None}}
    for key in TASK_KEYS:          # only when given: the keys of flights without them stay
        tl = values.get(key)
        if tl is not None:
            if isinstance(tl, bool) or not isinstance(tl, (int, float)) or not tl > 0:
                raise StudyError(f"{where}: {key} must be > 0 s, got {tl!r}")
            spec[key] = float(tl)
    return _plain(spec), label


def task_keywords(spec: dict) -> dict[str, float]:
    """The Task keywords a flight spec sets (time_limit, settle_budget): for Flight and for
    judging its recording alike."""
    return {k: spec[k] for k in TASK_KEYS if spec.get(k)}


def build_scenario(spec: dict):
    """The astrobee.scenario.Scenario a spec flies (overrides and realism applied)."""
    from astrobee.scenario import Scenario
    sc = spec["scenario"]
    if isinstance(sc, dict):
        base = Scenario.from_dict(sc, str(sc.get("name", "inline")))
    else:
        base = Scenario.load(sc)
    return parse_overrides({**(spec.get("overrides") or {}), "realism": spec.get("realism")},
                           source="study").apply(base)


def _block_size(block: Any, seeds: list[int]) -> int:
    """How many flights a block expands to, counted from its sizes alone (so a huge grid is
    refused before anything is built; malformed parts count 1 and are refused later)."""
    if not isinstance(block, dict):
        return 1
    grid = block.get("grid") if isinstance(block.get("grid"), dict) else {}
    n = 1
    for k, v in grid.items():
        if k != "seed" and isinstance(v, list):
            n *= max(1, len(v))
    seed_axis = grid.get("seed")
    block_seeds = block.get("seeds", seeds)
    n *= len(seed_axis) if isinstance(seed_axis, list) else (
        len(block_seeds) if isinstance(block_seeds, list) else 1)
    random = block.get("random")
    count = random.get("count", 1) if isinstance(random, dict) else 1
    if isinstance(count, int) and not isinstance(count, bool) and count > 1:
        n *= count
    return n


def _expand_block(block: dict, bi: int, base: dict, seeds: list[int], controllers: dict,
                  where: str) -> list[tuple[dict, dict, str]]:
    """(flight values, swept values, block name) for every flight of one block."""
    name = str(block.get("name") or f"block{bi}")
    bw = f"{where}: block {name!r}"
    _check_keys(block, BLOCK_KEYS, bw)
    fixed = _check_keys(block.get("set"), FLIGHT_KEYS, f"{bw} set")
    grid = _check_keys(block.get("grid"), FLIGHT_KEYS | {"seed", "case"}, f"{bw} grid")
    for k, v in grid.items():
        if not isinstance(v, list) or not v:
            raise StudyError(f"{bw} grid: {k!r} must be a non-empty list, got {v!r}")
    for i, case in enumerate(grid.get("case") or []):
        if not isinstance(case, dict) or not isinstance(case.get("name"), str):
            raise StudyError(f"{bw} grid: case {i} must be a mapping with a name and flight "
                             f"parameters, got {case!r}")
        _check_keys({k: v for k, v in case.items() if k != "name"}, FLIGHT_KEYS,
                    f"{bw} grid case {case['name']!r}")
    random = block.get("random")
    draws: list[dict] = [{}]
    if random is not None:
        _check_keys(random, {"count", "seed", "draw"}, f"{bw} random")
        count = random.get("count", 1)
        if isinstance(count, bool) or not isinstance(count, int) or count < 1:
            raise StudyError(f"{bw} random: count must be an integer >= 1, got {count!r}")
        dists = _check_keys(random.get("draw"), FLIGHT_KEYS, f"{bw} random draw")
        if not dists:
            raise StudyError(f"{bw} random: draw must name at least one parameter")
        rng = np.random.default_rng(int(random.get("seed", 0)))
        draws = [{k: _draw(rng, d, f"{bw} random draw {k!r}") for k, d in dists.items()}
                 for _ in range(count)]
    block_seeds = _seeds(block["seeds"], bw) if "seeds" in block else seeds
    axes = list(grid)
    out = []
    for combo in itertools.product(*(grid[a] for a in axes)):
        point = dict(zip(axes, combo))
        run_seeds = _seeds([point.pop("seed")], bw) if "seed" in point else block_seeds
        for draw in draws:
            for seed in run_seeds:
                values = copy.deepcopy(base)
                for src in (fixed, point, draw):
                    for k, v in src.items():
                        if k == "case":      # several parameters at once, named
                            for ck, cv in v.items():
                                if ck != "name":
                                    _set_path(values, str(ck), cv, bw)
                        else:
                            _set_path(values, str(k), v, bw)
                values["seed"] = seed
                swept = {k: (v["name"] if k == "case" else v)
                         for k, v in {**point, **draw}.items() if k != "controller"}
                out.append((values, _plain(swept), name))
    return out


def _check_report_settings(data: dict, controllers: dict, where: str) -> None:
    """The report's `pairs` (label pairs to compare; default every two) and `oracle`."""
    from .oracle_table import check_setting
    pairs = data.get("pairs")
    if pairs is not None and not (isinstance(pairs, list) and all(
            isinstance(p, list) and len(p) == 2 and all(x in controllers for x in p)
            for p in pairs)):
        raise StudyError(f"{where}: pairs must be a list of [label, label] of the controllers "
                         f"({', '.join(controllers)}), got {pairs!r}")
    if data.get("oracle") is not None and (why := check_setting(data["oracle"])):
        raise StudyError(f"{where}: {why}")


def load_study(path: str | Path) -> Study:
    """Read and expand a study file (StudyError, one line, for anything wrong in it)."""
    p = Path(path)
    where = f"study {p}"
    try:    # roszen.yamltext: a bad or too deeply nested document is one line, no RecursionError
        data = yamltext.load(p.read_text(), where)
    except FileNotFoundError:
        raise StudyError(f"{where}: no such file") from None
    except OSError as exc:
        raise StudyError(f"{where}: {exc.strerror or exc}") from None
    except yamltext.YamlError as exc:
        raise StudyError(str(exc)) from None
    return parse_study(data, p.stem, where, p)


def parse_study(data: Any, default_name: str = "study", where: str = "study",
                path: Path | None = None) -> Study:
    """Expand study data (the parsed YAML)."""
    if not isinstance(data, dict):
        raise StudyError(f"{where} must be a mapping (name, controllers, base, blocks...)")
    _check_keys(data, TOP_KEYS, where)
    labels = data.get("labels")
    if labels is not None and (not isinstance(labels, dict)
                               or not all(isinstance(v, str) for v in labels.values())):
        raise StudyError(f"{where}: labels must map swept keys to axis labels (text), "
                         f"got {labels!r}")
    name = str(data.get("name") or default_name)
    if not name.replace("_", "").replace("-", "").isalnum():
        raise StudyError(f"{where}: name must be letters, digits, '_' or '-', got {name!r}")
    controllers = _controllers(data.get("controllers"), where)
    _check_report_settings(data, controllers, where)
    base = copy.deepcopy(_check_keys(data.get("base"), FLIGHT_KEYS, f"{where}: base"))
    for k in [k for k in base if "." in str(k)]:
        v = base.pop(k)
        _set_path(base, str(k), v, f"{where}: base")
    if "time_limit" in data:
        base.setdefault("time_limit", data["time_limit"])
    seeds = _seeds(data.get("seeds"), where)
    metrics = data.get("metrics")
    if metrics is not None and (not isinstance(metrics, list)
                                or not all(isinstance(m, str) for m in metrics)):
        raise StudyError(f"{where}: metrics must be a list of column names, got {metrics!r}")
    blocks = data.get("blocks")
    if blocks is None:
        blocks = [{k: data[k] for k in ("grid", "random", "set") if k in data}]
    elif any(k in data for k in ("grid", "random", "set")):
        raise StudyError(f"{where}: give blocks, or a top-level grid/random/set, not both")
    if not isinstance(blocks, list) or not blocks:
        raise StudyError(f"{where}: blocks must be a non-empty list of mappings")
    planned = sum(_block_size(b, seeds) for b in blocks)
    if planned > MAX_FLIGHTS:
        raise StudyError(f"{where}: more than {MAX_FLIGHTS} flights ({planned} asked)")
    flights: list[FlightSpec] = []
    scenarios_ok: set[str] = set()
    for bi, block in enumerate(blocks):
        if not isinstance(block, dict):
            raise StudyError(f"{where}: block {bi} must be a mapping, got {block!r}")
        for values, swept, bname in _expand_block(block, bi, base, seeds, controllers, where):
            fw = f"{where}: block {bname!r}"
            spec, label = resolve_flight(values, controllers, fw)
            spec["seed"] = int(values["seed"])
            sc_key = json.dumps({k: spec[k] for k in ("scenario", "overrides", "realism")},
                                sort_keys=True, default=str)
            if sc_key not in scenarios_ok:
                try:
                    built = build_scenario(spec)
                except ValueError as exc:        # ScenarioError is a ValueError
                    raise StudyError(f"{fw}: {exc}") from None
                if not 1 <= len(built.robots) <= 2 or built.goal_position is None:
                    raise StudyError(f"{fw}: scenario {built.name!r} needs one or two robots "
                                     "and a goal (what an in-process Flight flies)")
                scenarios_ok.add(sc_key)
            flights.append(FlightSpec(flight_key(spec), spec, label, bname, swept, len(flights)))
            if len(flights) > MAX_FLIGHTS:
                raise StudyError(f"{where}: more than {MAX_FLIGHTS} flights")
    if not flights:
        raise StudyError(f"{where}: no flights")
    return Study(name, flights, metrics, data, path, str(data.get("description") or ""))
