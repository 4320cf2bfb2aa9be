"""log-report's columns (lapwrench.hardware.log.columns): a log's cycles gathered one at a time into the
numbers the report draws, the same values as the cycles' dicts, without holding the cycles."""

from __future__ import annotations

import math
import tracemalloc
from pathlib import Path
from typing import Any

import numpy as np
from hardware.log.support import record

from lapwrench.hardware.log import RunLogger, read_log
from lapwrench.hardware.log.columns import MAX_PANELS, MODES, CycleColumns, cycle_time, number
from lapwrench.hardware.log.report import read_for_report


def test_numbers_and_times_are_taken_as_they_come() -> None:
    assert number(2) == 2.0 and math.isnan(number(True)) and math.isnan(number("1")) and math.isnan(number(10**400))
    assert cycle_time({"t": 0.5}) == 0.5 and cycle_time({"t": 0}) == 0.0
    for bad in (-1e-9, 1e15, math.nan, math.inf, "soon", None, [1.0]):
        assert math.isnan(cycle_time({"t": bad}))


def test_columns_hold_each_cycles_values_and_nan_where_one_lacks_them() -> None:
    cols = CycleColumns()
    cycles: list[dict[str, Any]] = [
        {"t": 0.0, "q": [1, 2], "mode": "handle", "alarm": True, "wrenches": {"rcm": [1, 2, 3, 4, 5, 6]}},
        {"t": None, "q": [9] * 40},  # no time: left out, its joints not counted
        {"t": 0.001, "q": [3, "x", 5], "mode": "sideways", "wrenches": {"late": [1]}, "telemetry": {"z": {"a": 7}}},
        {"t": 0.002, "wrenches": {"rcm": [0] * 6}, "telemetry": {"z": {"b": 8}, "y": [1]}},
    ]
    for c in cycles:
        cols.add(c)
    assert (cols.n, cols.read, cols.joints) == (3, 4, 3)
    np.testing.assert_array_equal(cols.column("t"), [0.0, 0.001, 0.002])
    np.testing.assert_array_equal(cols.matrix("q", 3), [[1, 2, np.nan], [3, np.nan, 5], [np.nan] * 3])
    np.testing.assert_array_equal(cols.column("mode"), [MODES.index("handle"), -1, -1])
    np.testing.assert_array_equal(cols.column("alarm"), [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(cols.matrix("wrench rcm", 6), [[1, 2, 3, 4, 5, 6], [np.nan] * 6, [0] * 6])
    np.testing.assert_array_equal(cols.matrix("wrench late", 2), [[np.nan] * 2, [1, np.nan], [np.nan] * 2])
    assert cols.wrenches == {"rcm", "late"} and cols.telemetry == {"z": ["a", "b"], "y": []}
    np.testing.assert_array_equal(cols.telemetry_values("z", "b"), [np.nan, np.nan, 8.0])
    assert np.isnan(cols.column("no such field")).all() and len(cols.column("no such field")) == 3


def test_only_the_plotted_joints_cues_and_fields_are_kept_but_all_are_counted() -> None:
    cols = CycleColumns()
    many = {f"cue{i}": {f"f{j}": float(i * j) for j in range(MAX_PANELS + 4)} for i in range(MAX_PANELS + 2)}
    cols.add({"t": 0.0, "q": list(range(5000)), "telemetry": many})
    assert cols.joints == 5000 and len(cols.telemetry) == MAX_PANELS + 2
    assert all(len(fields) == MAX_PANELS + 4 for fields in cols.telemetry.values())
    assert cols.telemetry_values("cue3", "f5") == [15.0]
    assert np.isnan(cols.telemetry_values(f"cue{MAX_PANELS}", "f1")).all()  # not plotted: not kept
    assert np.isnan(cols.telemetry_values("cue3", f"f{MAX_PANELS}")).all()


def test_a_log_read_for_its_report_is_its_cycles_values_without_its_cycles(tmp_path: Path) -> None:
    """The report's numbers are those of the cycles load_log gives, and what stays in memory is a small
    fraction of the cycles' dicts (it was about 8 kB a cycle: 2 GB for a 200 s run)."""
    path = tmp_path / "run.mcap"
    rng = np.random.default_rng(1)
    with RunLogger(path, {"robot": "test"}, telemetry={"zoom": ("spread", "force")}, capacity=5000) as log:
        for k in range(3000):
            log.cycle(record(k, q=rng.normal(size=7), rcm_error=float(rng.random()),
                             telemetry={"zoom": (float(k), float(rng.random()))}))
    cycles = read_log(path)[0]
    tracemalloc.start()
    try:
        log_contents, cols = read_for_report(path)
        kept, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert log_contents.cycles == [] and cols.n == cols.read == 3000
    assert kept < 1500 * cols.n  # the columns: about 0.5 kB a cycle here
    np.testing.assert_array_equal(cols.column("rcm_error"), [c["rcm_error"] for c in cycles])
    np.testing.assert_array_equal(cols.matrix("q", 7), [c["q"] for c in cycles])
    np.testing.assert_array_equal(cols.telemetry_values("zoom", "force"), [c["telemetry"]["zoom"]["force"]
                                                                           for c in cycles])
    assert sorted(cols.wrenches) == sorted(cycles[0]["wrenches"])
