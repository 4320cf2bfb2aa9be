"""The study report's figures: box plots of a metric per parameter value, and the Pareto scatter.

Everything here is headless (matplotlib's Agg backend) and takes plain columns of the rows table
(:mod:`lapwrench.study.report` picks and cleans them). Non-finite values never reach a plot: the
helpers drop them, and a figure with nothing left to draw is not written.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TypeGuard

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

MAX_DISCRETE = 6
"""A numeric parameter with more distinct values than this is a random sample: it is binned."""

N_BINS = 5
"""At most this many quantile bins for a binned parameter."""

MISSING = "—"
"""How a missing text cell (None, NaN) is shown."""

LARGEST = 1e100
"""Metric values beyond this magnitude are left out of statistics and figures, as NaN and inf are."""


def text(value: object) -> str:
    """``value`` as a label: None and NaN become :data:`MISSING`, integers stay whole, other numbers keep
    4 significant digits."""
    if _is_na(value):
        return MISSING
    if isinstance(value, bool | np.bool_):
        return str(bool(value))
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating) and float(value).is_integer() and abs(float(value)) < 1e15:
        return str(int(value))  # a seed read back as float (its column held a NaN)
    if isinstance(value, float | np.floating):
        return f"{float(value):.4g}"
    return str(value)


def numeric(values: pd.Series | Sequence[object]) -> np.ndarray:
    """The values as floats: bools as 0/1, anything not a number (None, text) as NaN, a number beyond
    :data:`LARGEST` (a run that blew up) as ±inf, which is left out like inf: a figure's axis or a mean
    over such values would overflow."""
    series = values if isinstance(values, pd.Series) else pd.Series(list(values), dtype=object)
    out = pd.to_numeric(series.astype(object), errors="coerce").to_numpy(dtype=float, na_value=np.nan)
    with np.errstate(invalid="ignore"):
        return np.where(np.abs(out) > LARGEST, np.copysign(np.inf, out), out)


def _is_number(value: object) -> TypeGuard[int | float | np.integer | np.floating]:
    """A real number that is not a bool (bools are categories: True/False)."""
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool | np.bool_)


def _is_na(value: object) -> bool:
    """None, NaN, NaT or pandas' NA (a scalar missing value; a list or array is not one)."""
    return value is None or pd.isna(value) is True


def _is_missing(value: object) -> bool:
    """A missing value, or a number that is not finite (±inf)."""
    return _is_na(value) or (_is_number(value) and not math.isfinite(float(value)))


def _unique_range_labels(edges: np.ndarray) -> list[str]:
    """``lo–hi`` labels of consecutive edges, with the fewest significant digits that keep them distinct."""
    labels: list[str] = []
    for digits in range(3, 10):
        labels = [f"{lo:.{digits}g}–{hi:.{digits}g}" for lo, hi in itertools.pairwise(edges)]
        if len(set(labels)) == len(labels):
            break
    return labels


def param_groups(values: pd.Series) -> tuple[list[str | None], list[str]]:
    """Group label of each value of a parameter column, and the labels in display order.

    Numbers with at most :data:`MAX_DISCRETE` distinct values are their own groups, in numeric order.
    More distinct numbers (a random sample) fall into at most :data:`N_BINS` quantile bins labelled
    ``lo–hi`` (each bin holds (lo, hi], the first also lo). Anything else (text such as ``"fr3"``,
    bools, a mix) is grouped by its text, in text order. Missing values (None, NaN, ±inf) get ``None``.
    """
    raw = list(values)
    present = [v for v in raw if not _is_missing(v)]
    if present and all(_is_number(v) for v in present):
        distinct = sorted({float(v) for v in present})
        if len(distinct) <= MAX_DISCRETE:
            order = [text(v) for v in distinct]
            return [None if _is_missing(v) else text(v) for v in raw], order
        sample = np.asarray([float(v) for v in present])
        edges = np.unique(np.quantile(sample, np.linspace(0.0, 1.0, N_BINS + 1)))
        order = _unique_range_labels(edges)

        def bin_of(v: float) -> str:
            k = int(np.searchsorted(edges, v, side="left")) - 1
            return order[min(max(k, 0), len(order) - 1)]

        return [None if _is_missing(v) else bin_of(float(v)) for v in raw], order
    labels = [None if _is_missing(v) else text(v) for v in raw]
    return labels, sorted({lab for lab in labels if lab is not None})


def safe_name(column: str) -> str:
    """A column name as part of a file name: its ``p.``/``m.``/``s.`` prefix dropped, other than
    letters, digits, '-' and '_' replaced by '_'."""
    for prefix in ("p.", "m.", "s."):
        if column.startswith(prefix):
            column = column[len(prefix):]
            break
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in column) or "_"


def _save(fig: plt.Figure, path: Path) -> Path:
    """Write and close the figure."""
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _boxes(ax: plt.Axes, groups: list[tuple[str, np.ndarray]]) -> None:
    """Box plots of the groups side by side, each with its points jittered over it (seeded: the same
    rows always give the same picture)."""
    data = [vals for _, vals in groups]
    ax.boxplot(data, tick_labels=[lab for lab, _ in groups], showfliers=False, widths=0.6)
    rng = np.random.default_rng(0)
    for k, vals in enumerate(data, start=1):
        ax.plot(k + rng.uniform(-0.15, 0.15, len(vals)), vals, ".", ms=3, alpha=0.5, color="tab:blue")
    if len(groups) > 3 or max(len(lab) for lab, _ in groups) > 8:
        ax.tick_params(axis="x", labelrotation=30)


def _grid(n: int) -> tuple[plt.Figure, list[plt.Axes]]:
    """A figure with ``n`` panels, at most 3 a row."""
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.6 * rows), squeeze=False)
    flat = list(axes.ravel())
    for ax in flat[n:]:
        ax.set_visible(False)
    return fig, flat[:n]


def plot_distributions(
    panels: Sequence[str], groups: Sequence[str | None], order: Sequence[str], values: np.ndarray,
    path: Path, *, xlabel: str, ylabel: str,
) -> int:
    """One panel per distinct entry of ``panels`` (e.g. ``"grip · high"``), a box per group of ``order``.

    ``panels``, ``groups`` and ``values`` are aligned row by row; rows whose group is None or whose value
    is not finite are dropped, and so are empty groups and panels. Writes ``path`` if anything is left.
    Returns the number of values drawn (0: nothing written).
    """
    keep = np.isfinite(values) & np.array([g is not None for g in groups], dtype=bool)
    content: list[tuple[str, list[tuple[str, np.ndarray]]]] = []
    panel_arr, group_arr = np.asarray(panels, dtype=object), np.asarray(groups, dtype=object)
    for panel in sorted({p for p, k in zip(panels, keep, strict=True) if k}):
        in_panel = keep & (panel_arr == panel)
        boxes = [(g, values[in_panel & (group_arr == g)]) for g in order]
        boxes = [(g, v) for g, v in boxes if v.size]
        if boxes:
            content.append((panel, boxes))
    if not content:
        return 0
    fig, axes = _grid(len(content))
    for ax, (panel, boxes) in zip(axes, content, strict=True):
        _boxes(ax, boxes)
        ax.set(title=panel, xlabel=xlabel, ylabel=ylabel)
        ax.grid(axis="y", alpha=0.3)
    _save(fig, path)
    return int(sum(v.size for _, boxes in content for _, v in boxes))


def plot_pareto(
    x: np.ndarray, y: np.ndarray, scenarios: Sequence[str], front: np.ndarray, path: Path,
    *, xlabel: str, ylabel: str,
) -> Path:
    """Scatter of (x, y) coloured by scenario, the Pareto front (indices sorted by x) as a step line."""
    fig, ax = plt.subplots(figsize=(7.0, 4.8))
    names = np.asarray(scenarios, dtype=object)
    colors = plt.get_cmap("tab10")
    for k, name in enumerate(sorted(set(scenarios))):
        mask = names == name
        ax.scatter(x[mask], y[mask], s=14, alpha=0.6, color=colors(k % 10), label=str(name))
    if front.size:
        ax.step(x[front], y[front], where="post", color="k", lw=1.4, label="Pareto front")
        ax.scatter(x[front], y[front], s=36, facecolors="none", edgecolors="k")
    ax.set(xlabel=xlabel, ylabel=ylabel, title=f"{ylabel} against {xlabel} (both minimised)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path)
