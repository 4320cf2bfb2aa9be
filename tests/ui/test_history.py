"""The scrolling window of plotted signals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lapwrench.ui.history import MODES, History, mode_index


def test_the_window_keeps_the_latest_samples_oldest_first() -> None:
    h = History(capacity=4)
    for k in range(6):
        h.append(float(k), {"a": 10.0 * k})
    t, cols = h.window()
    np.testing.assert_array_equal(t, [2.0, 3.0, 4.0, 5.0])
    np.testing.assert_array_equal(cols["a"], [20.0, 30.0, 40.0, 50.0])
    assert len(h) == 4


def test_a_signal_missing_from_a_sample_is_a_gap_and_new_signals_appear() -> None:
    h = History(capacity=8)
    h.append(0.0, {"a": 1.0})
    h.append(1.0, {"b": 2.0})
    _t, cols = h.window(["a", "b", "c"])
    assert math.isnan(cols["a"][1]) and math.isnan(cols["b"][0])
    assert np.all(np.isnan(cols["c"]))
    assert h.names() == ["a", "b"]


def test_version_tells_readers_about_new_data_and_clear_empties() -> None:
    h = History(capacity=3)
    v = h.version
    h.append(0.0, {"a": 1.0})
    assert h.version > v
    h.clear()
    assert len(h) == 0 and h.window()[0].size == 0
    with pytest.raises(ValueError):
        History(capacity=1)


def test_mode_index_orders_the_modes_and_marks_holds() -> None:
    assert [mode_index(m) for m in MODES] == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert mode_index("held") == -1.0
    assert math.isnan(mode_index("dancing"))
