"""The control loop's records: a run's figures (percentiles, the summary) and the growable series."""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest

from lapwrench.loop_stats import Growable, LoopStats


def test_growable_keeps_every_value_across_its_chunks() -> None:
    g = Growable(chunk=4)
    for k in range(11):  # three chunks
        g.append(float(k))
    np.testing.assert_array_equal(g.array(), np.arange(11.0))
    assert g.n == 11 and g.dropped == 0
    assert Growable().array().shape == (0,) and Growable(width=2).array().shape == (0, 2)


def test_growable_never_copies_what_it_holds_and_keeps_the_last_rows() -> None:
    """Growing allocates a new chunk and never copies the old ones (a copy of a long run's series stalls
    the 1 kHz loop); beyond ``keep`` rows the oldest chunk goes."""
    big = Growable(width=8, chunk=1024)
    row = np.ones(8)
    for _ in range(16 * 1024):  # 16 full chunks, 1 MB
        big.append(row)
    tracemalloc.start()
    try:
        big.append(row)  # the first row of a new chunk
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2 * 1024 * 8 * 8  # one 64 kB chunk, not a copy of the 1 MB held
    g = Growable(chunk=4, keep=10)
    for k in range(30):
        g.append(float(k))
    out = g.array()
    np.testing.assert_array_equal(out, np.arange(20.0, 30.0))  # the last 10
    assert g.n == 30 and g.dropped == 20
    with pytest.raises(ValueError, match="keep"):
        Growable(keep=0)


def test_growable_rows_and_a_copy_the_caller_may_keep() -> None:
    g = Growable(width=3, chunk=2)
    rows = np.arange(15.0).reshape(5, 3)
    for r in rows:
        g.append(r)
    out = g.array()
    np.testing.assert_array_equal(out, rows)
    out[0, 0] = -1.0
    g.append(rows[0])
    assert g.array()[0, 0] == 0.0  # the returned array was a copy


def test_percentiles_of_the_cycle_and_compute_times() -> None:
    s = LoopStats(cycles=5, cycle_us=np.array([1000.0, 1000.0, 1000.0, 1000.0, 2000.0]),
                  compute_us=np.array([100.0, 200.0, 300.0, 400.0, 500.0]))  # fmt: skip
    assert s.percentile("cycle", 50) == 1000.0
    assert s.percentile("compute", 50) == 300.0
    assert s.percentile("compute", 100) == 500.0


def test_an_empty_run_has_no_percentiles() -> None:
    s = LoopStats()
    assert math.isnan(s.percentile("cycle", 99)) and math.isnan(s.percentile("compute", 50))
    summary = s.summary()
    assert summary["cycles"] == 0 and summary["rcm_error_measured_max_mm"] is None
    assert math.isnan(summary["cycle_p99_us"])  # type: ignore[arg-type]


def test_summary_names_units_and_converts_the_rcm_error_to_mm() -> None:
    s = LoopStats(
        cycles=3, cycle_us=np.full(3, 1000.0), compute_us=np.array([150.04, 150.06, 200.0]),
        rcm_error_measured=np.array([1e-4, 1.23456e-3, 5e-4]), robot_time=0.0034567, wall_time=0.01,
        deadline_misses=1, over_budget=2, alarm="rcm_error", stopped_at_rest=True,
    )  # fmt: skip
    summary = s.summary()
    assert summary["rcm_error_measured_max_mm"] == pytest.approx(1.2346)
    assert summary["robot_time_s"] == 0.003 and summary["wall_time_s"] == 0.01
    assert summary["compute_p50_us"] == 150.1 and summary["cycle_p99_us"] == 1000.0
    assert (summary["deadline_misses"], summary["over_budget_cycles"]) == (1, 2)
    assert summary["alarm"] == "rcm_error" and summary["stopped_at_rest"] is True
    unitless = {"cycles", "deadline_misses", "over_budget_cycles", "alarm", "stopped_at_rest"}
    assert all(k.endswith(("_s", "_us", "_mm")) for k in summary if k not in unitless)


def test_the_whole_runs_rcm_peak_outlives_the_series_window() -> None:
    s = LoopStats(cycles=3, rcm_error_measured=np.array([1e-4, 2e-4, 1e-4]), rcm_error_measured_max=3e-3)
    assert s.summary()["rcm_error_measured_max_mm"] == 3.0
