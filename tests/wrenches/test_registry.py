"""lapwrench.wrenches.registry: building the configured cues and the inputs they ask for."""

from __future__ import annotations

import pytest
from fake_plugins import FAKE, PEDAL, install

from lapwrench import plugins
from lapwrench.config import ConfigError, from_dict, load
from lapwrench.wrenches import InteractionCue, RcmCue, TrackingCue, ViscousCue
from lapwrench.wrenches.registry import build_cues, cue_class, input_specs


@pytest.fixture(autouse=True)
def _plugins(monkeypatch: pytest.MonkeyPatch) -> None:
    install(monkeypatch)


def test_the_default_configuration_builds_the_paper_cues_with_their_sections() -> None:
    cfg = load()
    cues = build_cues(cfg)
    assert [type(c) for c in cues] == [RcmCue, InteractionCue, TrackingCue, ViscousCue]
    assert cues[0].params is cfg.rcm and cues[2].params is cfg.tracking
    assert all(c.fused for c in cues) and cues[0].priority == "task"


def test_switched_off_cues_are_not_built() -> None:
    cues = build_cues(from_dict({"cues": {"tracking": {"enabled": False}, "spring": {"enabled": False}}}))
    assert [c.name for c in cues] == ["rcm", "interaction", "viscous"]


def test_plugin_cues_are_built_with_their_parameters_in_order() -> None:
    cues = build_cues(from_dict({"cues": {"b": {"type": "spring", "stiffness": 5}, "a": {"type": "sideways"}}}))
    assert [c.name for c in cues][-2:] == ["b", "a"] and cues[-2].params.stiffness == 5.0


def test_a_registered_object_that_is_not_a_cue_is_refused() -> None:
    with pytest.raises(ConfigError, match="not a lapwrench Cue"):
        cue_class("nope")


def test_the_inputs_a_cue_asks_for_are_looked_up() -> None:
    cues = build_cues(from_dict({"cues": {"pedal_hold": {}}}))
    assert input_specs(cues) == {"pedal": PEDAL}


def test_an_input_nobody_registered_is_a_config_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(FAKE[plugins.CUE_GROUP]["pedal_hold"], "inputs", ("sonar",))
    with pytest.raises(ConfigError, match="needs input 'sonar'"):
        build_cues(from_dict({"cues": {"pedal_hold": {}}}))


def test_an_input_registered_as_something_else_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(FAKE[plugins.CUE_GROUP]["pedal_hold"], "inputs", ("bad_input",))
    with pytest.raises(ConfigError, match="not an InputSpec"):
        build_cues(from_dict({"cues": {"pedal_hold": {}}}))
