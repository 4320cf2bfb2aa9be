"""The live plots: one line per cue, the scrolling window sent when it changed."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.ui.history import History
from lapwrench.ui.plots import LivePlots, chart_data, plot_specs
from lapwrench.ui.scene import cue_color

viser = pytest.importorskip("viser")


def specs(names: list[str]) -> list:
    return plot_specs(names, {n: cue_color(n, i) for i, n in enumerate(names)})


def test_the_cue_chart_has_a_line_per_cue() -> None:
    charts = specs(["rcm", "interaction", "my_plugin"])
    cue_chart = next(c for c in charts if c.title.startswith("cue forces"))
    assert [name for name, _, _ in cue_chart.lines] == ["|F| rcm", "|F| interaction", "|F| my_plugin"]
    assert any("RCM" in c.title for c in charts) and any("mode" in c.title for c in charts)


def test_chart_data_puts_time_first_and_fills_gaps() -> None:
    h = History(capacity=10)
    h.append(0.0, {"δ": 1.0})
    h.append(0.02, {})
    chart = next(c for c in specs(["rcm"]) if c.title.startswith("grip"))
    t, delta = chart_data(h, chart)
    np.testing.assert_array_equal(t, [0.0, 0.02])
    np.testing.assert_array_equal(delta, [1.0, 0.0])
    empty = chart_data(History(), chart)
    assert all(len(a) == 1 for a in empty)


def test_refresh_sends_only_new_windows() -> None:
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        h = History(capacity=10)
        plots = LivePlots(server.gui, h, specs(["rcm"]))
        assert len(plots.handles) == len(plots.specs)
        assert plots.refresh()
        assert not plots.refresh()
        h.append(1.0, {"RCM error (mm)": 0.5})
        assert plots.refresh()
        np.testing.assert_array_equal(plots.handles[0].data[1], [0.5])
    finally:
        server.stop()
