"""lapwrench.hardware.log.layout: the shipped Foxglove layout is the generated one, and names what the
logger writes."""

from __future__ import annotations

import json

from lapwrench.hardware.log.layout import build_layout, shipped_layout_path
from lapwrench.hardware.log.live import ROBOT_DESCRIPTION_TOPIC
from lapwrench.hardware.log.topics import CYCLE_TOPIC, IMAGE_TOPIC, WRENCH_TOPIC


def test_the_shipped_layout_is_up_to_date() -> None:
    assert shipped_layout_path().read_text().strip() == build_layout().strip(), (
        "regenerate it: python -m lapwrench.hardware.log.layout"
    )


def test_the_layout_shows_the_robot_the_image_and_plots_of_logged_fields() -> None:
    text = shipped_layout_path().read_text()
    layout = json.loads(text)
    assert layout["content"]["type"] == "split"
    for topic in (ROBOT_DESCRIPTION_TOPIC, IMAGE_TOPIC, WRENCH_TOPIC, f"{CYCLE_TOPIC}.rcm_error_measured",
                  f"{CYCLE_TOPIC}.mode", f"{CYCLE_TOPIC}.delta"):
        assert topic in text
