"""The page's live plots (viser's uPlot charts) over the scrolling window of
:class:`~lapwrench.ui.history.History`: physical RCM error, trocar force, |F| of every cue (one line
per cue name, whatever cues the configuration runs), δ, and the mode timeline.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from lapwrench.ui.history import MODES, History


@dataclass(frozen=True)
class PlotSpec:
    """One chart: its title and its lines (history signal name, label, colour)."""

    title: str
    lines: tuple[tuple[str, str, str], ...]
    step: bool = False  # a fixed y range over the modes (the mode timeline)


def plot_specs(cue_names: list[str], cue_colors: dict[str, tuple[int, int, int]]) -> list[PlotSpec]:
    """The charts of the page; the cue chart has a line per cue."""
    cue_lines = tuple((f"|F| {n}", n, "rgb({},{},{})".format(*cue_colors[n])) for n in cue_names)
    modes = ", ".join(f"{i} {m}" for i, m in enumerate(MODES))
    return [
        PlotSpec("physical RCM error (mm)", (("RCM error (mm)", "RCM error", "rgb(220,40,40)"),)),
        PlotSpec("trocar force (N)", (("trocar force (N)", "|F| trocar", "rgb(250,170,30)"),)),
        PlotSpec("cue forces |F| (N)", cue_lines),
        PlotSpec("grip gain δ", (("δ", "δ", "rgb(60,120,240)"),)),
        PlotSpec(f"mode ({modes}; -1 held)", (("mode", "mode", "rgb(90,90,90)"),), step=True),
    ]


def chart_data(history: History, spec: PlotSpec) -> tuple[np.ndarray, ...]:
    """The chart's arrays (time first) from the history; gaps (NaN) become 0 so the scales stay finite."""
    t, cols = history.window([name for name, _, _ in spec.lines])
    if len(t) == 0:
        t = np.zeros(1)
        cols = {name: np.zeros(1) for name, _, _ in spec.lines}
    return (t, *(np.nan_to_num(cols[name], nan=0.0) for name, _, _ in spec.lines))


class LivePlots:
    """The charts on the page, refreshed from the history when it has new samples."""

    def __init__(self, gui: Any, history: History, specs: list[PlotSpec]) -> None:
        self.history = history
        self.specs = specs
        self.handles: list[Any] = []
        self.updates = 0
        self._version = -1
        for spec in specs:
            series: list[dict[str, Any]] = [{"label": "t (s)"}]
            for _, label, color in spec.lines:
                series.append({"label": label, "stroke": color, "width": 2})
            scales: dict[str, Any] = {"x": {"time": False}}
            if spec.step:
                scales["y"] = {"auto": False, "range": [-1.2, len(MODES) - 0.8]}
            self.handles.append(gui.add_uplot(chart_data(history, spec), tuple(series), title=spec.title,
                                              scales=scales, aspect=3.0))

    def refresh(self) -> bool:
        """Send the window to the page if the history changed; returns whether it did."""
        version = self.history.version
        if version == self._version:
            return False
        self._version = version
        for handle, spec in zip(self.handles, self.specs, strict=True):
            handle.data = chart_data(self.history, spec)
        self.updates += 1
        return True
