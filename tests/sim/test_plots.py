"""The demo's figures (:mod:`lapwrench.sim.plots`), drawn from small synthetic results: one PNG per
scenario plot, every cue plotted with no code per cue, the snapshot strip."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest
from sim.report_data import N, disturbance, grip, hard_push, needle_search, trace

from lapwrench.config import load
from lapwrench.sim import plots
from lapwrench.sim.results import Run, ScenarioResult


def png_size(path: Path) -> tuple[int, int]:
    """(height, width) in pixels of a PNG written by the plots."""
    return mpimg.imread(path).shape[:2]


@pytest.mark.parametrize(
    ("plot", "result", "name"),
    [
        (plots.plot_grip, grip, "grip.png"),
        (plots.plot_disturbance, disturbance, "rcm_disturbance.png"),
        (plots.plot_hard_push, hard_push, "hard_push.png"),  # one run stopped before its first tick
    ],
)
def test_each_scenario_plot_writes_its_png(
    tmp_path: Path, plot: Callable[[ScenarioResult, Path], list[str]], result: Callable[[], ScenarioResult], name: str
) -> None:
    assert plot(result(), tmp_path) == [name]
    h, w = png_size(tmp_path / name)
    assert h > 300 and w > 1000


def test_the_tracking_plot_is_named_after_its_stem(tmp_path: Path) -> None:
    assert plots.plot_tracking_run(needle_search(), tmp_path, "needle_search") == ["needle_search.png"]
    assert png_size(tmp_path / "needle_search.png") == (825, 1430)  # 13 x 7.5 in at 110 dpi


def test_cue_columns_split_wrenches_from_telemetry() -> None:
    tr = trace(**{"cue:zoom": np.zeros((N, 6)), "cue:zoom.spread": np.ones(N), "cue:keep-out": np.zeros((N, 6))})
    assert plots.cue_columns(tr) == (["cue:zoom", "cue:keep-out"], ["cue:zoom.spread"])
    assert plots.cue_columns(trace()) == ([], [])
    assert plots.cue_columns(object()) == ([], [])  # not a trace: no columns, no cues


def test_a_result_without_cue_columns_draws_no_cue_plot(tmp_path: Path) -> None:
    assert plots.plot_cues(disturbance(), tmp_path, "rcm_disturbance") == []
    assert not list(tmp_path.iterdir())


def test_every_cue_is_plotted_with_no_code_per_cue(tmp_path: Path) -> None:
    wrench = np.tile([0.0, 0.0, 0.0, 3.0, 4.0, 0.0], (N, 1))
    runs = [Run(f"run {k}", trace(**{"cue:mine": wrench, "cue:mine.gain": np.ones(N)}), {}) for k in range(2)]
    assert plots.plot_cues(ScenarioResult("custom", runs, {}), tmp_path, "custom") == ["custom_cues.png"]
    h, w = png_size(tmp_path / "custom_cues.png")
    assert (h, w) == (round(2 * 2.6 * 110), 13 * 110)  # one row per run, telemetry beside the wrench


@pytest.mark.parametrize(("count", "panels"), [(1, 1), (4, 4), (20, 6)])
def test_the_snapshot_strip_shows_at_most_six_frames(tmp_path: Path, count: int, panels: int) -> None:
    shots = [(np.full((48, 64, 3), 10 * k, np.uint8), f"t={k}") for k in range(count)]
    assert plots.snapshot_strip(shots, load(), tmp_path / "strip.png") == "strip.png"
    assert png_size(tmp_path / "strip.png")[1] == 3 * panels * 110


# -- notes -------------------------------------------------------------------------------------------


def test_each_tracking_scenario_names_its_own_paper_figure() -> None:
    """The workflow's plot said "paper Fig. 7b" (the needle search's figure); it is Fig. 9."""
    assert plots.tracking_title("workflow") == "workflow: applied wrenches (paper Fig. 9)"
    assert plots.tracking_title("needle-search") == "needle-search: applied wrenches (paper Fig. 7b)"
    assert plots.tracking_title("mine") == "mine: applied wrenches"


@pytest.mark.parametrize(
    ("values", "scaled", "peak"),
    [
        (np.array([0.0, 0.005, -0.01]), np.array([0.0, 0.5, -1.0]), 0.01),  # metres beside newtons: visible
        (np.array([0.0, 40.0, np.nan, np.inf]), np.array([0.0, 1.0, np.nan, np.inf]), 40.0),
        (np.zeros(3), np.zeros(3), 1.0),
        (np.full(2, np.nan), np.full(2, np.nan), 1.0),
    ],
)
def test_telemetry_is_drawn_over_its_peak(values: np.ndarray, scaled: np.ndarray, peak: float) -> None:
    out, p = plots.scaled_to_peak(values)
    assert p == peak and np.array_equal(out, scaled, equal_nan=True)
