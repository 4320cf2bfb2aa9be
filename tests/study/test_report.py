"""The study report (lapwrench.study.report): Pareto front, counts, paper comparison, figures, failures,
and reports from degenerate rows tables. Rows are built by hand: no simulation, no Ray."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from matplotlib import image as mpimg

from lapwrench.study.report import Comparison, ReportSpec, pareto_front, write_report

NAN = float("nan")


def _row(run_id: str, scenario: str, label: str | None, seed: int, **cols: object) -> dict[str, object]:
    """One ok row with the bookkeeping columns filled in; ``cols`` adds or overrides columns."""
    row: dict[str, object] = {
        "run_id": run_id, "study": "t", "scenario": scenario, "label": label, "seed": seed,
        "status": "ok", "error": None, "node": "node0001", "wall_s": 1.0, "config": "",
    }
    row.update({k.replace("__", "."): v for k, v in cols.items()})
    return row


def _sweep_rows(n_seeds: int = 12) -> pd.DataFrame:
    """Two runs per job of a grip-like scenario, a swept numeric, a text and a random continuous parameter."""
    rng = np.random.default_rng(7)
    rows = []
    for seed in range(n_seeds):
        common = {
            "p.world.surgeon_force": (0.5, 1.0, 1.5)[seed % 3],
            "p.robot": ("panda", "fr3")[seed % 2],
            "p.world.trocar_stiffness": float(rng.uniform(0.5, 2.0)),
        }
        for label in ("low", "high"):
            rows.append(_row(f"{seed:016x}", "grip", label, seed, node=f"node000{seed % 2}", wall_s=2.5, **{
                **common,
                "m.completion_time_s": float(rng.normal(10.0, 2.0)),
                "m.rcm_error_max_mm": float(rng.uniform(0.1, 1.5)),
            }))
    return pd.DataFrame(rows)


SWEEP_SPEC = ReportSpec(
    title="Sweep", params=("p.world.surgeon_force", "p.robot", "p.world.trocar_stiffness"),
    metrics=("m.completion_time_s",),
)
TEXT_ONLY = ReportSpec(title="Text", params=("p.robot",), metrics=(), pareto=None)
"""A spec that draws nothing: for the tests of the tables."""


# --- pareto_front --------------------------------------------------------------------------------


def test_pareto_front_keeps_non_dominated_points_sorted_by_x() -> None:
    x = np.array([1.0, 2.0, 3.0, 2.0, NAN, 1.0, 3.0, 0.5, 4.0])
    y = np.array([3.0, 2.0, 1.0, 3.0, 0.0, 3.0, 2.0, np.inf, 0.5])
    # 3 (2,3) and 6 (3,2) are dominated; 4 and 7 are not finite; 5 equals 0 (a tie, both kept)
    assert pareto_front(x, y).tolist() == [0, 5, 1, 2, 8]


def test_pareto_front_equal_x_keeps_only_the_lower_y() -> None:
    assert pareto_front(np.array([1.0, 1.0, 2.0]), np.array([2.0, 1.0, 0.5])).tolist() == [1, 2]


def test_pareto_front_of_nothing_finite_is_empty() -> None:
    assert pareto_front(np.array([NAN, 1.0]), np.array([1.0, NAN])).size == 0
    assert pareto_front(np.array([]), np.array([])).size == 0


def test_pareto_front_rejects_mismatched_shapes() -> None:
    with pytest.raises(ValueError, match="same shape"):
        pareto_front(np.zeros(3), np.zeros(2))


# --- counts and the paper comparison -------------------------------------------------------------


def test_report_counts_jobs_rows_nodes_and_worker_time(tmp_path: Path) -> None:
    rows = _sweep_rows(4)  # 4 jobs × 2 runs, wall 2.5 s each job, 2 nodes
    failed = _row("f" * 16, "grip", None, 99, status="failed", error="RuntimeError: x", node="node0002", wall_s=1.0)
    rows = pd.concat([rows, pd.DataFrame([failed])], ignore_index=True)
    text = write_report(rows, tmp_path, TEXT_ONLY, notes=["cluster: local", "ray 2.x"]).read_text()
    assert "**Jobs:** 5 · **rows:** 9 (ok 8, failed 1) · **nodes:** 3" in text
    assert "(11.0 s)" in text  # 4 × 2.5 + 1.0, each job counted once although it has two rows
    assert "- cluster: local" in text and "- ray 2.x" in text


def test_comparison_row_has_median_and_iqr_of_the_matching_finite_ok_values(tmp_path: Path) -> None:
    high = [7.25, 8.5, 9.125, 10.75, 12.5, 13.0625]
    rows = [_row(f"{k:016x}", "grip", "high", k, **{"m.completion_time_s": v}) for k, v in enumerate(high)]
    rows += [
        _row("a" * 16, "grip", "high", 50, **{"m.completion_time_s": NAN}),
        _row("b" * 16, "grip", "high", 51, **{"m.completion_time_s": np.inf}),
        _row("c" * 16, "grip", "high", 52, **{"m.completion_time_s": None}),
        _row("d" * 16, "grip", "low", 53, **{"m.completion_time_s": 99.0}),  # another run
        _row("e" * 16, "other", "high", 54, **{"m.completion_time_s": 99.0}),  # another scenario
        _row("f" * 16, "grip", "high", 55, status="failed", error="E: x", **{"m.completion_time_s": 99.0}),
    ]
    spec = ReportSpec(
        title="Cmp", params=(), metrics=(),
        compare=(
            Comparison("Fig. 4 completion time, high grip", "grip", "high", "m.completion_time_s", 8.0, "s"),
            Comparison("no such metric", "grip", None, "m.nope", None),
        ),
    )
    text = write_report(pd.DataFrame(rows), tmp_path, spec).read_text()
    q25, med, q75 = np.percentile(high, [25, 50, 75])
    mean = np.mean(high)
    assert (f"| Fig. 4 completion time, high grip | 6 of 9 | {med:.4g} | {q25:.4g}–{q75:.4g} | {mean:.4g} | 8 | s |"
            in text)
    assert "| no such metric | 0 of 10 | — | — | — | — |  |" in text


# --- distributions --------------------------------------------------------------------------------


def _assert_image(path: Path) -> None:
    img = mpimg.imread(path)
    assert img.ndim == 3 and img.shape[0] > 50 and img.shape[1] > 50


@pytest.fixture(scope="module")
def sweep_report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The report of :func:`_sweep_rows`, written once for the figure tests."""
    return write_report(_sweep_rows(), tmp_path_factory.mktemp("sweep"), SWEEP_SPEC)


@pytest.mark.parametrize(
    "png",
    [
        "dist_world_surgeon_force__completion_time_s.png",  # swept numeric, 3 values
        "dist_robot__completion_time_s.png",  # text
        "dist_world_trocar_stiffness__completion_time_s.png",  # random continuous, binned
        "pareto.png",
    ],
)
def test_figures_are_written_valid_and_embedded(sweep_report: Path, png: str) -> None:
    _assert_image(sweep_report.parent / png)
    assert f"]({png})" in sweep_report.read_text()


def test_metric_only_figures_when_no_parameter_is_swept(tmp_path: Path) -> None:
    spec = ReportSpec(title="Seeds", params=(), metrics=("m.completion_time_s", "m.rcm_error_max_mm"))
    text = write_report(_sweep_rows(), tmp_path, spec).read_text()
    for png in ("dist__completion_time_s.png", "dist__rcm_error_max_mm.png"):
        _assert_image(tmp_path / png)
        assert f"]({png})" in text


def test_pareto_table_lists_the_front(tmp_path: Path) -> None:
    rows = pd.DataFrame([
        _row("0" * 16, "s", "a", 0, **{"p.k": 1, "m.completion_time_s": 5.0, "m.rcm_error_max_mm": 0.9}),
        _row("1" * 16, "s", "a", 1, **{"p.k": 2, "m.completion_time_s": 6.0, "m.rcm_error_max_mm": 0.95}),
        _row("2" * 16, "s", "a", 2, **{"p.k": 3, "m.completion_time_s": 7.0, "m.rcm_error_max_mm": 0.2}),
    ])
    text = write_report(rows, tmp_path, ReportSpec(title="P", params=(), metrics=())).read_text()
    assert "| 0000000000000000 | s | a | 1 | 5 | 0.9 |" in text
    assert "| 2222222222222222 | s | a | 3 | 7 | 0.2 |" in text
    assert "1111111111111111" not in text


# --- failures and degenerate tables ---------------------------------------------------------------


def test_failures_table_escapes_pipes_and_line_breaks(tmp_path: Path) -> None:
    rows = _sweep_rows(2)
    bad = _row("f" * 16, "grip", None, 7, status="failed", error="ValueError: a | b\nsecond line",
               **{"p.robot": "ur5"})
    text = write_report(pd.concat([rows, pd.DataFrame([bad])], ignore_index=True), tmp_path, TEXT_ONLY).read_text()
    line = next(ln for ln in text.splitlines() if ln.startswith("| ffffffffffffffff"))
    assert "ValueError: a \\| b<br>second line" in line
    header = text.splitlines()[text.splitlines().index(line) - 2]
    assert line.replace("\\|", "").count("|") == header.count("|")
    assert "No failed runs." not in text


def test_no_failures_says_so(tmp_path: Path) -> None:
    assert "No failed runs." in write_report(_sweep_rows(2), tmp_path, TEXT_ONLY).read_text()


def test_all_failed_rows_still_give_a_report(tmp_path: Path) -> None:
    rows = pd.DataFrame([
        _row(f"{k:016x}", "grip", None, k, status="failed", error=f"RuntimeError: {k}", **{"p.robot": "fr3"})
        for k in range(3)
    ])
    spec = ReportSpec(title="Broken", params=("p.robot",), metrics=("m.completion_time_s",),
                      compare=(Comparison("c", "grip", None, "m.completion_time_s", 1.0),))
    out = tmp_path / "deep" / "out"  # created on the way
    text = write_report(rows, out, spec).read_text()
    assert "(ok 0, failed 3)" in text
    assert "RuntimeError: 2" in text
    assert "| c | 0 of 0 | — | — | — | 1 |  |" in text
    assert not list(out.glob("*.png"))


def test_rows_without_metrics_or_columns_still_give_a_report(tmp_path: Path) -> None:
    rows = pd.DataFrame([_row("0" * 16, "grip", "high", 0, **{"p.flag": True}),
                         _row("1" * 16, "grip", "low", 1, **{"p.flag": False})])
    spec = ReportSpec(title="Empty", params=("p.flag", "p.absent"), metrics=("m.completion_time_s",))
    text = write_report(rows, tmp_path, spec).read_text()
    assert "**rows:** 2 (ok 2, failed 0)" in text
    assert "## Distributions" in text and "## Failures" in text
    assert not list(tmp_path.glob("*.png"))
    bare = write_report(pd.DataFrame(), tmp_path / "bare", spec).read_text()
    assert "**Jobs:** 0 · **rows:** 0" in bare


def test_metrics_too_large_to_plot_are_left_out_not_a_crash(tmp_path: Path) -> None:
    """±1e308 (a run that blew up) made matplotlib fail ("arange: cannot compute length") and the sweep end
    in a traceback after its runs; the mean of two such values is inf. They are left out now, as inf is."""
    rows = pd.DataFrame([
        _row("0" * 16, "grip", "high", 0, m__completion_time_s=1e308, m__rcm_error_max_mm=-1e308, p__x=1.0),
        _row("1" * 16, "grip", "high", 1, m__completion_time_s=-1e308, m__rcm_error_max_mm=1e308, p__x=2.0),
        _row("2" * 16, "grip", "high", 2, m__completion_time_s=5.0, m__rcm_error_max_mm=0.5, p__x=1.0),
    ])
    spec = ReportSpec(title="Huge", params=("p.x",), metrics=("m.completion_time_s", "m.rcm_error_max_mm"),
                      compare=(Comparison("c", "grip", "high", "m.completion_time_s", 6.0),))
    text = write_report(rows, tmp_path, spec).read_text()
    assert "| c | 1 of 3 | 5 | 5–5 | 5 | 6 |  |" in text  # the one finite, plottable value
    assert "inf" not in text and "nan" not in text.lower()
    assert (tmp_path / "pareto.png").exists() and (tmp_path / "dist_x__completion_time_s.png").exists()
