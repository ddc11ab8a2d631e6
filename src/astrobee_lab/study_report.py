"""The report of a study: markdown tables per block (success rate, contacts, clearance, relative
speed, tracking error, compute, wall time per controller and swept value) and plots (success
rate vs each numeric swept variable per controller; minimum bag clearance distributions),
written to the study folder as report.md and plots/*.png."""
from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path
from typing import Any

# (column, header, how to aggregate, format)
SUMMARY = (
    ("success", "success", "rate", "{:.0%}"),
    ("contacts", "flights w/ contact", "count_pos", "{:d}"),
    ("min_bag_clearance", "min bag clearance m (min / median)", "min_med", "{:.3f} / {:.3f}"),
    ("peak_bag_robot_speed", "peak bag-robot speed m/s (median)", "median", "{:.3f}"),
    ("rms_position_error", "RMS tracking error mm (median)", "median_mm", "{:.1f}"),
    ("compute_ms_median", "compute per cycle ms (median / p99)", "med_p99", "{:.2f} / {:.1f}"),
    ("wall_time", "wall time s (median)", "median", "{:.1f}"),
)


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


def aggregate(rows: list[dict]) -> dict[str, str]:
    """One summary line's cells for a group of rows."""
    out = {"n": str(len(rows))}
    for col, head, how, fmt in SUMMARY:
        vals = [_num(r.get(col)) for r in rows]
        fin = [v for v in vals if math.isfinite(v)]
        if how == "rate":
            cell = fmt.format(sum(bool(r.get("success")) is True for r in rows) / len(rows)) if rows else "-"
            ok = sum(bool(r.get("success")) is True for r in rows)
            cell = f"{cell} ({ok}/{len(rows)})"
        elif not fin:
            cell = "-"
        elif how == "count_pos":
            cell = fmt.format(sum(v > 0 for v in fin))
        elif how == "min_med":
            cell = fmt.format(min(fin), _median(fin))
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


def block_table(rows: list[dict], swept: list[str]) -> str:
    """Markdown table of one block: one line per (swept values, controller)."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    labels: list[str] = []
    for r in rows:
        labels += [r["label"]] if r["label"] not in labels else []
        groups[tuple(r.get(c) for c in swept) + (r["label"],)].append(r)
    order = sorted(groups, key=lambda k: tuple(_key(v) for v in k[:-1]) + (labels.index(k[-1]),))
    heads = [*swept, "controller", "n", *(h for _, h, _, _ in SUMMARY)]
    lines = ["| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
    for k in order:
        cells = aggregate(groups[k])
        lines.append("| " + " | ".join([*(str(v) for v in k[:-1]), k[-1], cells["n"],
                                         *(cells[h] for _, h, _, _ in SUMMARY)]) + " |")
    return "\n".join(lines)


def _numeric(rows: list[dict], col: str) -> bool:
    vals = {r.get(col) for r in rows}
    return len(vals) > 1 and all(math.isfinite(_num(v)) for v in vals)


def _plots(study_name: str, block: str, rows: list[dict], swept: list[str], out: Path) -> list[Path]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    made = []
    labels = list(dict.fromkeys(r["label"] for r in rows))
    for col in swept:
        if not _numeric(rows, col):
            continue
        fig, ax = plt.subplots(figsize=(6, 4))
        for lab in labels:
            by: dict[float, list[bool]] = defaultdict(list)
            for r in rows:
                if r["label"] == lab:
                    by[_num(r.get(col))].append(r.get("success") is True)
            xs = sorted(by)
            ax.plot(xs, [sum(by[x]) / len(by[x]) for x in xs], "o-", label=f"{lab} (n/pt={len(by[xs[0]])})")
        ax.set_xlabel(col)
        ax.set_ylabel("success rate")
        ax.set_ylim(-0.05, 1.05)
        ax.set_title(f"{study_name}: {block}")
        ax.grid(alpha=0.3)
        ax.legend()
        path = out / f"success_vs_{col.replace('.', '_')}_{block}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        plt.close(fig)
        made.append(path)
    data = [[_num(r.get("min_bag_clearance")) for r in rows if r["label"] == lab] for lab in labels]
    data = [[v for v in d if math.isfinite(v)] for d in data]
    if any(data):
        fig, ax = plt.subplots(figsize=(6, 4))
        keep = [(lab, d) for lab, d in zip(labels, data) if d]
        ax.boxplot([d for _, d in keep], showfliers=False)
        for i, (_, d) in enumerate(keep, 1):
            ax.plot([i + 0.08 * ((j % 5) - 2) for j in range(len(d))], d, ".", alpha=0.6)
        ax.set_xticks(range(1, len(keep) + 1), [lab for lab, _ in keep])
        ax.axhline(0.0, color="r", lw=0.8)
        ax.set_ylabel("minimum bag clearance (m)")
        ax.set_title(f"{study_name}: {block}")
        ax.grid(alpha=0.3)
        path = out / f"clearance_{block}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        plt.close(fig)
        made.append(path)
    return made


def write_report(study: Any, rows: list[dict], folder: str | Path) -> Path:
    """report.md (+ plots/) of the study's finished rows; returns the report's path."""
    folder = Path(folder)
    plots = folder / "plots"
    plots.mkdir(parents=True, exist_ok=True)
    total = len(study.flights)
    errors = [r for r in rows if r.get("status") == "error"]
    rows = [r for r in rows if r.get("status") != "error"]   # not flown: no verdict to count
    lines = [f"# Study {study.name}", ""]
    if study.description:
        lines += [study.description.strip(), ""]
    lines += [f"{len(rows)} of {total} rows flown"
              + (f", {len(errors)} ended in an error (left out below; flown again on resume: "
                 + "; ".join(sorted({str(r.get('cause'))[:100] for r in errors})) + ")"
                 if errors else "")
              + ". Table: results.csv; per flight: flights/<key>.json.", ""]
    blocks = list(dict.fromkeys(f.block for f in study.flights))
    if len(blocks) > 1 and rows:
        lines += ["## All flights, per controller", "", block_table(rows, []), ""]
    for b in blocks:
        brows = [r for r in rows if r["block"] == b]
        swept = list(dict.fromkeys(c for f in study.flights if f.block == b for c in f.swept))
        swept = [c for c in swept if c != "seed" and len({r.get(c) for r in brows}) > 1] if brows else swept
        lines += [f"## {b}", ""]
        if not brows:
            lines += ["(no finished flights)", ""]
            continue
        lines += [block_table(brows, swept), ""]
        try:
            made = _plots(study.name, b, brows, swept, plots)
        except ImportError:
            made = []
        lines += [f"![{p.stem}](plots/{p.name})" for p in made] + [""]
        fails = [r for r in brows if r.get("success") is not True]
        if fails:
            lines += ["Failures:", ""]
            lines += [f"- {r['label']} seed {r.get('seed')} "
                      + " ".join(f"{c}={r.get(c)}" for c in swept)
                      + f": {str(r.get('cause'))[:160]}" for r in fails[:40]]
            if len(fails) > 40:
                lines.append(f"- ... {len(fails) - 40} more")
            lines.append("")
    path = folder / "report.md"
    path.write_text("\n".join(lines))
    return path
