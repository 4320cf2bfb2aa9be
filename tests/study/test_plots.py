"""The study report's figures and their helpers (lapwrench.study.plots): grouping a parameter column,
labels, file names, and the figures themselves (headless)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib import image as mpimg

from lapwrench.study.plots import (
    MISSING,
    N_BINS,
    numeric,
    param_groups,
    plot_distributions,
    plot_pareto,
    safe_name,
    text,
)


def test_few_numbers_are_their_own_groups_in_numeric_order() -> None:
    labels, order = param_groups(pd.Series([10.0, 2.0, 0.5, 2.0, None, float("nan")]))
    assert order == ["0.5", "2", "10"]
    assert labels == ["10", "2", "0.5", "2", None, None]


def test_many_numbers_fall_into_at_most_five_quantile_bins() -> None:
    values = np.random.default_rng(3).uniform(0.0, 1.0, 200)
    labels, order = param_groups(pd.Series(values))
    assert 2 <= len(order) <= N_BINS and len(set(order)) == len(order)
    counts = pd.Series(labels).value_counts()
    assert set(counts.index) == set(order) and counts.sum() == 200
    assert counts.min() >= 200 // N_BINS - 2  # quantile bins are about equally full
    lowest = [v for v, lab in zip(values, labels, strict=True) if lab == order[0]]
    highest = [v for v, lab in zip(values, labels, strict=True) if lab == order[-1]]
    assert max(lowest) < min(highest)


def test_text_bool_and_mixed_values_are_grouped_by_text() -> None:
    assert param_groups(pd.Series(["fr3", "panda", None, "fr3"])) == (["fr3", "panda", None, "fr3"], ["fr3", "panda"])
    assert param_groups(pd.Series([True, False, True]))[1] == ["False", "True"]
    assert param_groups(pd.Series([1.0, "x"], dtype=object))[1] == ["1", "x"]


def test_text_and_numeric_helpers() -> None:
    assert [text(v) for v in (None, float("nan"), 3, 99.0, 0.123456, True, "a|b")] == [
        MISSING, MISSING, "3", "99", "0.1235", "True", "a|b"]
    got = numeric(pd.Series([True, 2, None, "x", float("inf")], dtype=object))
    assert got[:2].tolist() == [1.0, 2.0] and np.isnan(got[2]) and np.isnan(got[3]) and np.isinf(got[4])


def test_safe_name_drops_the_prefix_and_odd_characters() -> None:
    assert safe_name("p.world.surgeon_force") == "world_surgeon_force"
    assert safe_name("m.force/back (N)") == "force_back__N_"


def test_distributions_are_drawn_per_panel_and_group(tmp_path: Path) -> None:
    panels = ["a"] * 4 + ["b"] * 4
    groups = ["x", "y", "x", None, "x", "y", "y", "y"]
    values = np.array([1.0, 2.0, 3.0, 4.0, np.nan, 5.0, np.inf, 6.0])
    path = tmp_path / "d.png"
    assert plot_distributions(panels, groups, ["x", "y"], values, path, xlabel="p", ylabel="m") == 5
    assert mpimg.imread(path).ndim == 3


def test_nothing_finite_writes_no_figure(tmp_path: Path) -> None:
    path = tmp_path / "none.png"
    assert plot_distributions(["a", "a"], ["x", None], ["x"], np.array([np.nan, 1.0]), path, xlabel="p",
                              ylabel="m") == 0
    assert not path.exists()


def test_pareto_figure_is_written(tmp_path: Path) -> None:
    x, y = np.array([1.0, 2.0, 3.0]), np.array([3.0, 1.0, 2.0])
    path = plot_pareto(x, y, ["s", "s", "t"], np.array([0, 1]), tmp_path / "p.png", xlabel="x", ylabel="y")
    assert mpimg.imread(path).shape[0] > 100
