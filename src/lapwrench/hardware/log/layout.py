"""The Foxglove layout shipped with lapwrench (``lapwrench/data/foxglove/lapwrench.json``), built with
foxglove-sdk's layout classes so that its topics and paths are those the logger writes.

Left: the 3D panel (the robot from :data:`~.live.ROBOT_DESCRIPTION_TOPIC` driven by the logged
transforms, the scope pose and the wrench arrows); right: the laparoscope image above plots of the
RCM error (reference and measured), the grip gain δ and the wrench forces of the paper's cues, and
the mode timeline. Regenerate the file with ``python -m lapwrench.hardware.log.layout``
(``tests/hardware/log/test_layout.py`` fails when it is stale).
"""

from __future__ import annotations

import sys
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from lapwrench.hardware.log.live import ROBOT_DESCRIPTION_TOPIC
from lapwrench.hardware.log.topics import CYCLE_TOPIC, IMAGE_TOPIC, POSE_TOPIC, WRENCH_TOPIC

if TYPE_CHECKING:
    from foxglove.layouts import PlotSeries

LAYOUT_FILE = "data/foxglove/lapwrench.json"
PLOTTED_CUES = ("rcm", "interaction", "tracking", "viscous")
AXES = ("x", "y", "z")


def _series(path: str, label: str) -> PlotSeries:
    from foxglove.layouts import PlotSeries

    return PlotSeries(value=path, label=label, enabled=True, timestamp_method="receiveTime")


def build_layout() -> str:
    """The layout as Foxglove's JSON (the "Import layout" format)."""
    from foxglove import layouts as L  # noqa: N812 (the layout classes read better qualified)

    urdf = L.BaseRendererUrdfLayerSettings(
        layer_id="foxglove.Urdf", label="lapwrench arm and scope", source_type="topic", topic=ROBOT_DESCRIPTION_TOPIC,
        instance_id="lapwrench-urdf", display_mode="visual",
    )
    three_d = L.ThreeDeePanel(
        title="arm, scope and wrenches",
        config=L.ThreeDeeConfig(
            layers={"lapwrench-urdf": urdf},
            topics={WRENCH_TOPIC: L.BaseRendererSceneUpdateTopicSettings(visible=True),
                    POSE_TOPIC: L.BaseRendererPoseTopicSettings(visible=True)},
        ),
    )
    image_mode = L.ImageModeConfig(image_topic=IMAGE_TOPIC)
    image = L.ImagePanel(title="laparoscope", config=L.ImageConfig(image_mode=image_mode))
    rcm = L.PlotPanel(title="RCM error (m)", config=L.PlotConfig(paths=[
        _series(f"{CYCLE_TOPIC}.rcm_error", "reference"), _series(f"{CYCLE_TOPIC}.rcm_error_measured", "measured"),
    ], time_window_mode="sliding", following_view_width=20.0))
    grip = L.PlotPanel(title="grip gain δ", config=L.PlotConfig(paths=[_series(f"{CYCLE_TOPIC}.delta", "δ")],
                                                              time_window_mode="sliding", following_view_width=20.0))
    forces = L.PlotPanel(title="cue forces (N, {B})", config=L.PlotConfig(paths=[
        _series(f'{CYCLE_TOPIC}.wrenches[:]{{name=="{cue}"}}.w[{3 + i}]', f"{cue} F{axis}")
        for cue in PLOTTED_CUES for i, axis in enumerate(AXES)
    ], time_window_mode="sliding", following_view_width=20.0))
    modes = L.StateTransitionsPanel(title="mode", config=L.StateTransitionsConfig(paths=[
        L.StateTransitionsSeries(value=f"{CYCLE_TOPIC}.mode", label="mode", timestamp_method="receiveTime"),
    ]))
    right = L.SplitContainer(direction="column", items=[
        L.SplitItem(proportion=2, content=image), L.SplitItem(content=rcm), L.SplitItem(content=forces),
        L.SplitItem(content=grip), L.SplitItem(proportion=0.6, content=modes),
    ])
    content = L.SplitContainer(direction="row", items=[L.SplitItem(proportion=3, content=three_d),
                                                       L.SplitItem(proportion=2, content=right)])
    return L.Layout(content=content).to_json()


def shipped_layout_path() -> Path:
    return Path(str(resources.files("lapwrench").joinpath(LAYOUT_FILE)))


if __name__ == "__main__":
    shipped_layout_path().write_text(build_layout() + "\n")
    sys.stdout.write(f"wrote {shipped_layout_path()}\n")
