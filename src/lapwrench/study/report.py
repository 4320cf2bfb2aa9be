"""The study report: one Markdown page with PNG figures, written from the rows table of a study.

The rows table has one row per Run of a job (see ``runner``): ``run_id``, ``scenario``, ``label``,
``seed``, the swept parameters ``p.<key>``, ``status``/``error``, ``node``, ``wall_s`` and the metrics
``m.<name>``/``s.<name>``. :func:`write_report` turns it into ``report.md`` with five parts:

1. a summary line (jobs, rows, ok/failed, nodes, worker time) and the caller's notes;
2. the paper's values beside the study's median and IQR (:class:`Comparison`);
3. each metric's distribution per parameter value (box plots, random samples binned by quantile);
4. a trade-off scatter (by default RCM error against completion time) with its Pareto front;
5. the failed jobs with their errors.

Only ok rows enter statistics and plots, and only their finite values: a run that failed, a metric the
scenario does not have (NaN) or an infinite value is left out rather than breaking the page. Any part
that has nothing to show says so in one sentence, and the report is always written.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from lapwrench.study.plots import MISSING, numeric, param_groups, plot_distributions, plot_pareto, safe_name, text
from lapwrench.study.spec import Comparison, ReportSpec

MAX_FAILURES = 200
"""At most this many failed rows are listed; the rest are counted."""

MAX_ERROR_CHARS = 500
"""An error text longer than this is cut (the full text stays in the rows table)."""


def pareto_front(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Indices of the points no other point dominates, both coordinates minimised, sorted by x (then y).

    A point dominates another when it is no worse in both and better in one; equal points do not
    dominate each other, so duplicates on the front are all kept. Non-finite points are left out.
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if x.shape != y.shape:
        raise ValueError(f"pareto_front: x and y must have the same shape, got {x.shape} and {y.shape}")
    idx = np.flatnonzero(np.isfinite(x) & np.isfinite(y))
    order = idx[np.lexsort((y[idx], x[idx]))]
    front: list[int] = []
    best = np.inf
    for i in order:
        if y[i] < best:
            front.append(int(i))
            best = y[i]
        elif front and x[i] == x[front[-1]] and y[i] == y[front[-1]]:
            front.append(int(i))
    return np.asarray(front, dtype=np.intp)


# --- small helpers over the rows table -------------------------------------------------------------


def _column(rows: pd.DataFrame, name: str) -> pd.Series:
    """The column, or a column of None when the table lacks it."""
    if name in rows.columns:
        return rows[name]
    return pd.Series([None] * len(rows), index=rows.index, dtype=object)


def _ok(rows: pd.DataFrame) -> pd.DataFrame:
    """The rows of runs that finished."""
    return rows[_column(rows, "status").astype(object) == "ok"]


def _failed(rows: pd.DataFrame) -> pd.DataFrame:
    """The rows of jobs that raised."""
    return rows[_column(rows, "status").astype(object) == "failed"]


def _param_columns(rows: pd.DataFrame) -> list[str]:
    """Every ``p.<key>`` column, in table order."""
    return [c for c in rows.columns if str(c).startswith("p.")]


def _finite(values: np.ndarray) -> np.ndarray:
    """The finite values only."""
    return values[np.isfinite(values)]


def cell(value: object) -> str:
    """A Markdown table cell: numbers with 4 significant digits, '|' escaped, line breaks as ``<br>``."""
    s = text(value)
    if len(s) > MAX_ERROR_CHARS:
        s = s[:MAX_ERROR_CHARS] + "…"
    s = s.replace("\\", "\\\\").replace("|", "\\|")
    return s.replace("\r\n", "<br>").replace("\n", "<br>").replace("\r", "<br>")


def _table(header: Sequence[str], body: Sequence[Sequence[object]]) -> list[str]:
    """A Markdown table."""
    lines = ["| " + " | ".join(cell(h) for h in header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in body]
    return lines


def _duration(seconds: float) -> str:
    """``1234.5`` → ``"20 min 34 s (1234.5 s)"``."""
    whole = round(seconds)
    h, rem = divmod(whole, 3600)
    m, s = divmod(rem, 60)
    parts = ([f"{h} h"] if h else []) + ([f"{m} min"] if h or m else []) + [f"{s} s"]
    return f"{' '.join(parts)} ({seconds:.1f} s)"


def _run_key(rows: pd.DataFrame) -> list[str]:
    """``"scenario · label"`` of each row (the label left out when there is none)."""
    keys = []
    for scen, lab in zip(_column(rows, "scenario"), _column(rows, "label"), strict=True):
        keys.append(text(scen) if text(lab) == MISSING else f"{text(scen)} · {text(lab)}")
    return keys


# --- the sections -----------------------------------------------------------------------------------


def _summary(rows: pd.DataFrame, notes: Sequence[str]) -> list[str]:
    """The counts of jobs, rows, outcomes and nodes, the summed worker time, and the notes."""
    run_ids = _column(rows, "run_id")
    jobs = rows.drop_duplicates("run_id") if "run_id" in rows.columns else rows
    wall = float(_finite(numeric(_column(jobs, "wall_s"))).sum())
    line = (
        f"**Jobs:** {run_ids.nunique()} · **rows:** {len(rows)} (ok {len(_ok(rows))}, failed {len(_failed(rows))})"
        f" · **nodes:** {_column(rows, 'node').nunique()} · **worker time:** {_duration(wall)}"
    )
    return [line, "", *[f"- {n}" for n in notes], *([""] if notes else [])]


def comparison_stats(rows: pd.DataFrame, comp: Comparison) -> tuple[int, int, float, float, float, float]:
    """(n, total, median, q25, q75, mean) of the comparison's metric: n finite values among the ``total``
    matching ok rows (a grip run that never completed has no completion time). NaN statistics when n
    is 0. Quantiles are numpy's default (linear interpolation); the mean of a 0/1 metric is a share."""
    ok = _ok(rows)
    mask = _column(ok, "scenario").astype(object) == comp.scenario
    if comp.run is not None:
        mask &= _column(ok, "label").astype(object) == comp.run
    total = int(mask.sum())
    vals = _finite(numeric(_column(ok[mask], comp.metric)))
    if not vals.size:
        return 0, total, np.nan, np.nan, np.nan, np.nan
    q25, med, q75 = np.percentile(vals, [25.0, 50.0, 75.0])
    return int(vals.size), total, float(med), float(q25), float(q75), float(np.mean(vals))


def _comparisons(rows: pd.DataFrame, spec: ReportSpec) -> list[str]:
    """The paper's values beside the study's median, IQR and mean."""
    if not spec.compare:
        return []
    body = []
    for comp in spec.compare:
        n, total, med, q25, q75, mean = comparison_stats(rows, comp)
        iqr = f"{text(q25)}–{text(q75)}" if n else MISSING
        paper = MISSING if comp.paper is None or not np.isfinite(comp.paper) else comp.paper
        body.append([comp.label, f"{n} of {total}", med if n else MISSING, iqr, mean if n else MISSING, paper,
                     comp.unit])
    intro = ("Median, interquartile range (25th–75th percentile) and mean over the finished runs; "
             "n of N: runs with a value among the matching runs (a grip level never completed has none).")
    return ["## Paper beside the study", "", intro, "", *_table(
        ["figure", "n of N", "median", "IQR (q25–q75)", "mean", "paper", "unit"], body), ""]


def _resolve(rows: pd.DataFrame, name: str, prefix: str) -> str | None:
    """The column ``name`` (or ``prefix + name``) if the table has it."""
    for candidate in (name, prefix + name):
        if candidate in rows.columns:
            return candidate
    return None


def _distributions(rows: pd.DataFrame, out: Path, spec: ReportSpec) -> list[str]:
    """One box-plot figure per (parameter, metric); per metric only, when no parameter is present."""
    ok = _ok(rows)
    metrics = [m for m in (_resolve(rows, m, "m.") for m in spec.metrics) if m is not None]
    params = [p for p in (_resolve(rows, p, "p.") for p in spec.params) if p is not None]
    lines = ["## Distributions", ""]
    if not metrics or ok.empty:
        return [*lines, "No finished run has any of the metrics asked for; nothing to plot.", ""]
    keys = _run_key(ok)
    drawn = 0
    for param in params:
        groups, order = param_groups(_column(ok, param))
        for metric in metrics:
            name = f"dist_{safe_name(param)}__{safe_name(metric)}.png"
            n = plot_distributions(keys, groups, order, numeric(ok[metric]), out / name, xlabel=param, ylabel=metric)
            if n:
                drawn += 1
                lines += [f"![{metric} per {param}]({name})", "",
                          f"*{metric} per value of {param}, one panel per scenario · run ({n} values).*", ""]
    if not params:
        for metric in metrics:
            name = f"dist__{safe_name(metric)}.png"
            n = plot_distributions([metric] * len(ok), keys, sorted(set(keys)), numeric(ok[metric]), out / name,
                                   xlabel="scenario · run", ylabel=metric)
            if n:
                drawn += 1
                lines += [f"![{metric}]({name})", "", f"*{metric} per scenario · run ({n} values).*", ""]
    if not drawn:
        lines += ["No finished run has a finite value of the metrics asked for; nothing to plot.", ""]
    return lines


def _pareto(rows: pd.DataFrame, out: Path, spec: ReportSpec) -> list[str]:
    """The (x, y) scatter with its Pareto front, and the front as a table."""
    if spec.pareto is None:
        return []
    xcol, ycol = spec.pareto
    lines = ["## Trade-off and Pareto front", ""]
    ok = _ok(rows)
    x, y = numeric(_column(ok, xcol)), numeric(_column(ok, ycol))
    keep = np.isfinite(x) & np.isfinite(y)
    if not keep.any():
        return [*lines, f"No finished run has both {xcol} and {ycol}; no trade-off to show.", ""]
    pts = ok[keep]
    x, y = x[keep], y[keep]
    front = pareto_front(x, y)
    plot_pareto(x, y, [text(s) for s in _column(pts, "scenario")], front, out / "pareto.png", xlabel=xcol, ylabel=ycol)
    params = _param_columns(rows)
    body = [
        [pts["run_id"].iloc[i] if "run_id" in pts.columns else MISSING, _column(pts, "scenario").iloc[i],
         _column(pts, "label").iloc[i], *[pts[p].iloc[i] for p in params], x[i], y[i]]
        for i in front
    ]
    lines += [
        f"![{ycol} against {xcol}](pareto.png)", "",
        f"*{len(x)} finished runs; the black step line is the Pareto front: no run is better in both "
        f"{xcol} and {ycol} than a run on it.*", "",
        *_table(["run_id", "scenario", "label", *params, xcol, ycol], body), "",
    ]
    return lines


def _failures(rows: pd.DataFrame) -> list[str]:
    """The failed jobs with their parameters and errors."""
    failed = _failed(rows)
    lines = ["## Failures", ""]
    if failed.empty:
        return [*lines, "No failed runs.", ""]
    params = _param_columns(rows)
    shown = failed.head(MAX_FAILURES)
    cols = ["run_id", "scenario", "seed", *params, "error"]
    body = [[_column(shown, c).iloc[i] for c in cols] for i in range(len(shown))]
    lines += [f"{len(failed)} failed job(s); each keeps its config in the rows table.", "", *_table(cols, body)]
    if len(failed) > len(shown):
        lines.append(f"\n… and {len(failed) - len(shown)} more (see the rows table).")
    return [*lines, ""]


def write_report(rows: pd.DataFrame, out: Path, spec: ReportSpec, *, notes: Sequence[str] = ()) -> Path:
    """Write ``out/report.md`` and its PNG figures from the study's rows; returns the report's path.

    ``out`` is created if missing. Every part that has nothing to show says so; nothing in ``rows``
    (missing columns, NaN/inf/None, text parameters, no finished run) stops the report.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = rows.reset_index(drop=True)
    lines = [f"# {spec.title}", ""]
    lines += _summary(rows, notes)
    lines += _comparisons(rows, spec)
    lines += _distributions(rows, out, spec)
    lines += _pareto(rows, out, spec)
    lines += _failures(rows)
    path = out / "report.md"
    path.write_text("\n".join(lines).rstrip("\n") + "\n", encoding="utf-8")
    return path
