"""The report of a study: per block, a table (success rate with its Wilson 95% interval,
contacts, clearance, relative speed, tracking error, compute, wall time per controller and swept
value), paired per-seed comparisons of the controllers (McNemar's exact p) and plots (success
rate with its interval vs each numeric swept knob per controller, minimum bag clearance per
controller), written to the study folder as report.md + plots/*.png and as one self-contained
report.html (the same tables, the plots inline: html).

Axis and column labels come from the study file's `labels:` (swept knob -> what a reader should
read, units included: `realism.disturbances.0.magnitude: bump on the bag (N)`); a knob without
one is named by its key.
"""
from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field
from itertools import combinations
from pathlib import Path
from typing import Any

from .oracle_table import oracle_rows, oracle_setting
from .oracle_table import load as load_oracle
from .stats import paired, signed_rank, wilson

MARKERS = "osD^v"   # success plots: a marker per group of 10 controllers (the colours cycle)

# (column, header, how to aggregate, format)
SUMMARY = (
    ("success", "success", "rate", "{:.0%}"),
    ("success", "success 95% interval", "wilson", "{:.0%}-{:.0%}"),
    ("contacts", "flights w/ contact", "count_pos", "{:d}"),
    ("min_bag_clearance", "min bag clearance m (min / median)", "min_med", "{:.3f} / {:.3f}"),
    ("time_to_rest", "time to rest s (median of those at rest)", "median", "{:.1f}"),
    ("max_attitude_excursion", "largest attitude excursion rad (median / max)", "med_max",
     "{:.2f} / {:.2f}"),
    ("final_attitude_error", "final attitude error rad (median / max)", "med_max",
     "{:.2f} / {:.2f}"),
    ("peak_bag_robot_speed", "peak bag-robot speed m/s (median)", "median", "{:.3f}"),
    ("rms_position_error", "RMS tracking error mm (median)", "median_mm", "{:.1f}"),
    ("compute_ms_median", "compute per cycle ms (median / p99)", "med_p99", "{:.2f} / {:.1f}"),
    ("wall_time", "wall time s (median)", "median", "{:.1f}"),
)
# paired continuous metrics (Wilcoxon signed-rank over the seeds both controllers have a value
# of): (column, header, scale, format of the median paired difference)
CONTINUOUS = (
    ("min_bag_clearance", "min bag clearance m", 1.0, "{:+.3f}"),
    ("time_to_rest", "time to rest s", 1.0, "{:+.1f}"),
    ("max_attitude_excursion", "attitude excursion rad", 1.0, "{:+.2f}"),
    ("final_attitude_error", "final attitude error rad", 1.0, "{:+.2f}"),
    ("rms_position_error", "RMS error mm", 1e3, "{:+.1f}"),
    ("compute_ms_median", "compute ms", 1.0, "{:+.2f}"),
)


@dataclass
class Doc:
    """The report as parts ('h1'|'h2'|'p'|'table'|'img'|'ul', payload), written as markdown
    and as HTML from the same parts."""

    parts: list[tuple[str, Any]] = field(default_factory=list)

    def add(self, kind: str, payload: Any) -> None:
        self.parts.append((kind, payload))

    def markdown(self) -> str:
        out: list[str] = []
        for kind, x in self.parts:
            if kind == "h1":
                out += [f"# {x}", ""]
            elif kind == "h2":
                out += [f"## {x}", ""]
            elif kind == "h3":
                out += [f"### {x}", ""]
            elif kind == "p":
                out += [x, ""]
            elif kind == "table":
                heads, rows = x
                out += ["| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
                out += ["| " + " | ".join(r) + " |" for r in rows] + [""]
            elif kind == "img":
                alt, path, rel = x
                out += [f"![{alt}]({rel})", ""]
            elif kind == "ul":
                out += [f"- {item}" for item in x] + [""]
        return "\n".join(out)


def _num(v: Any) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return math.nan
    return f


def _median(xs: list[float]) -> float:
    xs = sorted(x for x in xs if math.isfinite(x))
    if not xs:
        return math.nan
    n = len(xs)
    return xs[n // 2] if n % 2 else 0.5 * (xs[n // 2 - 1] + xs[n // 2])


def _ok(r: dict) -> bool:
    return r.get("success") is True


def aggregate(rows: list[dict]) -> dict[str, str]:
    """One summary line's cells for a group of rows."""
    out = {"n": str(len(rows))}
    ok = sum(_ok(r) for r in rows)
    for col, head, how, fmt in SUMMARY:
        vals = [_num(r.get(col)) for r in rows]
        fin = [v for v in vals if math.isfinite(v)]
        if how == "rate":
            cell = f"{fmt.format(ok / len(rows))} ({ok}/{len(rows)})" if rows else "-"
        elif how == "wilson":
            cell = fmt.format(*wilson(ok, len(rows))) if rows else "-"
        elif not fin:
            cell = "-"
        elif how == "count_pos":
            cell = fmt.format(sum(v > 0 for v in fin))
        elif how == "min_med":
            cell = fmt.format(min(fin), _median(fin))
        elif how == "med_max":
            cell = fmt.format(_median(fin), max(fin))
        elif how == "med_p99":
            p99 = [_num(r.get("compute_ms_p99")) for r in rows]
            cell = fmt.format(_median(fin), _median(p99))
        elif how == "median_mm":
            cell = fmt.format(1e3 * _median(fin))
        else:
            cell = fmt.format(_median(fin))
        out[head] = cell
    return out


def _key(v: Any) -> tuple:
    f = _num(v)
    return (0, f, "") if math.isfinite(f) else (1, 0.0, str(v))


def labels_of(study: Any) -> dict[str, str]:
    """Swept knob -> its human label (the study file's `labels:`)."""
    raw = (getattr(study, "source", None) or {}).get("labels") or {}
    return {str(k): str(v) for k, v in raw.items()} if isinstance(raw, dict) else {}


def _groups(rows: list[dict], swept: list[str]) -> tuple[dict[tuple, list[dict]], list[tuple]]:
    groups: dict[tuple, list[dict]] = defaultdict(list)
    labels: list[str] = []
    for r in rows:
        labels += [r["label"]] if r["label"] not in labels else []
        groups[tuple(r.get(c) for c in swept) + (r["label"],)].append(r)
    order = sorted(groups, key=lambda k: tuple(_key(v) for v in k[:-1]) + (labels.index(k[-1]),))
    return groups, order


def block_rows(rows: list[dict], swept: list[str], names: dict[str, str] | None = None
               ) -> tuple[list[str], list[list[str]]]:
    """(headers, cells) of one block's table: one line per (swept values, controller)."""
    names = names or {}
    groups, order = _groups(rows, swept)
    heads = [*(names.get(c, c) for c in swept), "controller", "n", *(h for _, h, _, _ in SUMMARY)]
    out = []
    for k in order:
        cells = aggregate(groups[k])
        out.append([*(str(v) for v in k[:-1]), k[-1], cells["n"],
                    *(cells[h] for _, h, _, _ in SUMMARY)])
    return heads, out


def block_table(rows: list[dict], swept: list[str], names: dict[str, str] | None = None) -> str:
    """Markdown table of one block (block_rows)."""
    doc = Doc()
    doc.add("table", block_rows(rows, swept, names))
    return doc.markdown().rstrip("\n")


def paired_rows(rows: list[dict], swept: list[str], names: dict[str, str] | None = None,
                pairs: list[tuple[str, str]] | None = None
                ) -> tuple[list[str], list[list[str]]] | None:
    """(headers, cells) of the paired per-seed comparisons of two controllers at the same swept
    values over the seeds both flew: McNemar's exact p on success, then per continuous metric
    the median paired difference (second - first) with Wilcoxon's signed-rank p. Every two
    controllers, or the study's `pairs`. None when no two share a seed."""
    names = names or {}
    by: dict[tuple, dict[str, dict[int, dict]]] = defaultdict(lambda: defaultdict(dict))
    for r in rows:
        seed = r.get("seed")
        if isinstance(seed, (int, float)) and not isinstance(seed, bool):
            by[tuple(r.get(c) for c in swept)][r["label"]][int(seed)] = r
    metrics = [m for m in CONTINUOUS if any(math.isfinite(_num(r.get(m[0]))) for r in rows)]
    out = []
    for values in sorted(by, key=lambda k: tuple(_key(v) for v in k)):
        flown = list(by[values])
        todo = combinations(flown, 2) if pairs is None else \
            [(a, b) for a, b in pairs if a in flown and b in flown]
        for a, b in todo:
            ra, rb = by[values][a], by[values][b]
            p = paired(a, b, {s: _ok(r) for s, r in ra.items()}, {s: _ok(r) for s, r in rb.items()})
            if p is None:
                continue
            cells = [*(str(v) for v in values), f"{a} vs {b}", str(p.seeds), str(p.both),
                     f"{p.only_a} ({a})", f"{p.only_b} ({b})", str(p.neither), f"{p.p_value:.3g}"]
            for col, _, scale, fmt in metrics:
                w = signed_rank({s: scale * _num(r.get(col)) for s, r in ra.items()},
                                {s: scale * _num(r.get(col)) for s, r in rb.items()})
                cells.append("-" if w is None else
                             f"{fmt.format(w.median_diff)} (p {w.p_value:.2g}, n {w.n})")
            out.append(cells)
    if not out:
        return None
    heads = [*(names.get(c, c) for c in swept), "pair", "seeds paired", "both succeed",
             "only the first", "only the second", "neither", "McNemar exact p",
             *(f"{h}: median paired diff, second - first (Wilcoxon p, n)" for _, h, _, _ in metrics)]
    return heads, out


def _numeric(rows: list[dict], col: str) -> bool:
    vals = {r.get(col) for r in rows}
    return len(vals) > 1 and all(math.isfinite(_num(v)) for v in vals)


def _plots(study_name: str, block: str, rows: list[dict], swept: list[str], out: Path,
           names: dict[str, str]) -> list[tuple[str, Path]]:
    """(caption, PNG) of the block's plots."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    made = []
    labels = list(dict.fromkeys(r["label"] for r in rows))
    for col in swept:
        if not _numeric(rows, col):
            continue
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        for i, lab in enumerate(labels):
            by: dict[float, list[bool]] = defaultdict(list)
            for r in rows:
                if r["label"] == lab:
                    by[_num(r.get(col))].append(_ok(r))
            xs = sorted(by)
            if not xs:
                continue
            rate = [sum(by[x]) / len(by[x]) for x in xs]
            ci = [wilson(sum(by[x]), len(by[x])) for x in xs]
            # >= 0: at 0 or 20 of 20 the interval's end equals the rate up to rounding
            err = [[max(r - lo, 0.0) for r, (lo, _) in zip(rate, ci)],
                   [max(hi - r, 0.0) for r, (_, hi) in zip(rate, ci)]]
            shift = (i - (len(labels) - 1) / 2) * 0.012 * (max(xs) - min(xs) or 1.0)
            # matplotlib cycles 10 colours: past them the line is dashed and the marker other
            ax.errorbar([x + shift for x in xs], rate, yerr=err, color=f"C{i % 10}",
                        fmt=MARKERS[i // 10 % len(MARKERS)] + ("-", "--")[i // 10 % 2],
                        capsize=4, label=f"{lab} ({len(by[xs[0]])} seeds a point)")
        what = names.get(col, col)
        ax.set_xlabel(what)
        ax.set_ylabel("success rate (bars: Wilson 95% interval)")
        ax.set_ylim(-0.05, 1.05)
        ax.yaxis.set_major_formatter(matplotlib.ticker.PercentFormatter(1.0))
        ax.set_title(f"{study_name}, {block}: success vs {what}", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        path = out / f"success_vs_{col.replace('.', '_')}_{block}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        plt.close(fig)
        made.append((f"success rate vs {what}, per controller", path))
    data = [[_num(r.get("min_bag_clearance")) for r in rows if r["label"] == lab] for lab in labels]
    data = [[v for v in d if math.isfinite(v)] for d in data]
    if any(data):
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        keep = [(lab, d) for lab, d in zip(labels, data) if d]
        ax.boxplot([d for _, d in keep], showfliers=False)
        for i, (_, d) in enumerate(keep, 1):
            ax.plot([i + 0.08 * ((j % 5) - 2) for j in range(len(d))], d, ".", alpha=0.6)
        ax.set_xticks(range(1, len(keep) + 1), [lab for lab, _ in keep])
        ax.axhline(0.0, color="r", lw=0.8)
        ax.set_xlabel("controller")
        ax.set_ylabel("minimum cargo bag clearance to the walls (m)")
        ax.set_title(f"{study_name}, {block}: closest approach of the bag, per flight",
                     fontsize=10)
        ax.grid(alpha=0.3)
        path = out / f"clearance_{block}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        plt.close(fig)
        made.append(("minimum cargo bag clearance per flight, per controller", path))
    return made


def build(study: Any, rows: list[dict], folder: Path) -> Doc:
    """The report's parts (plots written to folder/plots)."""
    plots = folder / "plots"
    plots.mkdir(parents=True, exist_ok=True)
    names = labels_of(study)
    total = len(study.flights)
    errors = [r for r in rows if r.get("status") == "error"]
    rows = [r for r in rows if r.get("status") != "error"]   # not flown: no verdict to count
    doc = Doc()
    doc.add("h1", f"Study {study.name}")
    if study.description:
        doc.add("p", study.description.strip())
    doc.add("p", f"{len(rows)} of {total} rows flown"
            + (f", {len(errors)} ended in an error (left out below; flown again on resume: "
               + "; ".join(sorted({str(r.get('cause'))[:100] for r in errors})) + ")"
               if errors else "")
            + ". Table: results.csv; per flight: flights/<key>.json. Success rates with their "
              "Wilson 95% interval; paired comparisons over the seeds both controllers flew "
              "(McNemar's exact test on the seeds where only one succeeded; Wilcoxon's "
              "signed-rank test on the continuous metrics' paired differences).")
    source = getattr(study, "source", None) or {}
    pairs = [tuple(p) for p in source["pairs"]] if source.get("pairs") else None
    oracle = oracle_setting(source)
    answers = None
    if oracle is not None:
        answers, where = load_oracle(oracle[0])
        doc.add("p", "The oracle (offline optimal control of the reduced pair model, the bump "
                     "known in advance) as the upper bound: per condition, the seeds it finds "
                     f"feasible and each controller's success on them; {where}.")
    specs = {f.key: f.spec for f in study.flights}
    blocks = list(dict.fromkeys(f.block for f in study.flights))
    if len(blocks) > 1 and rows:
        doc.add("h2", "All flights, per controller")
        doc.add("table", block_rows(rows, []))
    for b in blocks:
        brows = [r for r in rows if r["block"] == b]
        swept = list(dict.fromkeys(c for f in study.flights if f.block == b for c in f.swept))
        swept = [c for c in swept if c != "seed" and len({r.get(c) for r in brows}) > 1] if brows else swept
        doc.add("h2", b)
        if not brows:
            doc.add("p", "(no finished flights)")
            continue
        doc.add("table", block_rows(brows, swept, names))
        if answers is not None and (oracle[1] is None or b in oracle[1]):
            bound = oracle_rows(brows, swept, specs, answers, names)
            if bound is not None:
                doc.add("h3", f"{b}: against the oracle")
                doc.add("table", bound)
        compared = paired_rows(brows, swept, names, pairs)
        if compared is not None:
            doc.add("h3", f"{b}: paired per seed")
            doc.add("table", compared)
        try:
            made = _plots(study.name, b, brows, swept, plots, names)
        except ImportError:
            made = []
        for caption, p in made:
            doc.add("img", (caption, p, f"plots/{p.name}"))
        fails = [r for r in brows if not _ok(r)]
        if fails:
            items = [f"{r['label']} seed {r.get('seed')} "
                     + " ".join(f"{names.get(c, c)}={r.get(c)}" for c in swept)
                     + f": {str(r.get('cause'))[:160]}" for r in fails[:40]]
            if len(fails) > 40:
                items.append(f"... {len(fails) - 40} more")
            doc.add("p", "Failures:")
            doc.add("ul", items)
    return doc


def write_report(study: Any, rows: list[dict], folder: str | Path) -> Path:
    """report.md (+ plots/) and report.html (self-contained) of the study's finished rows;
    returns report.md's path."""
    from .html import to_html
    folder = Path(folder)
    doc = build(study, rows, folder)
    path = folder / "report.md"
    path.write_text(doc.markdown())
    (folder / "report.html").write_text(to_html(doc, f"Study {study.name}"))
    return path
