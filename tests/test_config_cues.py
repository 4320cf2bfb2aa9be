"""lapwrench.config_cues: the ``cues:`` section of the configuration."""

from __future__ import annotations

import pytest
from fake_plugins import SpringParams, install

from lapwrench.config import ConfigError, from_dict, load, to_dict
from lapwrench.config_cues import DEFAULT_CUES, PAPER_CUES


@pytest.fixture(autouse=True)
def _plugins(monkeypatch: pytest.MonkeyPatch) -> None:
    install(monkeypatch)


def test_the_paper_cues_run_by_default() -> None:
    assert load().cues == DEFAULT_CUES
    assert [c.name for c in DEFAULT_CUES] == list(PAPER_CUES)


def test_a_plugin_cue_is_added_after_the_paper_cues_with_validated_parameters() -> None:
    cfg = from_dict({"cues": {"spring": {"stiffness": 80, "target": [0.4, 0.0, 0.2]}}})
    spring = cfg.cue("spring")
    assert [c.name for c in cfg.cues] == [*PAPER_CUES, "spring"]
    assert spring is not None and spring.params == SpringParams((0.4, 0.0, 0.2), 80.0)


def test_two_instances_of_one_type_under_two_names() -> None:
    cfg = from_dict({"cues": {"left": {"type": "spring"}, "right": {"type": "spring", "stiffness": 10}}})
    assert cfg.cue("left").type == cfg.cue("right").type == "spring"  # type: ignore[union-attr]


def test_a_paper_cue_can_be_switched_off_but_not_the_rcm() -> None:
    assert from_dict({"cues": {"tracking": {"enabled": False}}}).cue("tracking") is None
    with pytest.raises(ConfigError, match="primary task"):
        from_dict({"cues": {"rcm": {"enabled": False}}})
    with pytest.raises(ConfigError, match="primary task"):
        from_dict({"cues": {"rcm": {"type": "spring"}}})


def test_a_paper_cue_cannot_run_under_another_name() -> None:
    with pytest.raises(ConfigError, match="own name"):
        from_dict({"cues": {"second_tracking": {"type": "tracking"}}})


@pytest.mark.parametrize(
    ("cues", "key", "words"),
    [
        ({"spring": {"stiffness": -1}}, "cues.spring.stiffness", "must lie in"),
        ({"spring": {"stiffness": "hard"}}, "cues.spring.stiffness", "must be a number"),
        ({"spring": {"target": [0.1, 0.2]}}, "cues.spring.target", "list of 3 numbers"),
        ({"spring": {"target": [0.1, 0.2, 9.0]}}, "cues.spring.target[2]", "must lie in"),
        ({"spring": {"target": [0.1, 0.2, float("nan")]}}, "cues.spring.target[2]", "finite"),
        ({"spring": {"bogus": 1}}, "cues.spring.bogus", "unknown config key"),
        ({"spring": {"enabled": "yes"}}, "cues.spring.enabled", "true or false"),
        ({"spring": [1, 2]}, "cues.spring", "must be a mapping"),
        ({"warp": {}}, "cues.warp", "no cue named 'warp'"),
        ({"x": {"type": 5}}, "cues.x.type", "a cue name"),
        ({"Bad Name": {}}, "cues", "lower-case identifier"),
        ({"tracking": {"F_max": 3}}, "cues.tracking.F_max", "'tracking:' section"),
    ],
)
def test_bad_cue_entries_are_one_line_errors_naming_the_key(cues: dict, key: str, words: str) -> None:
    with pytest.raises(ConfigError) as err:
        from_dict({"cues": cues})
    assert err.value.key == key and words in str(err.value) and "\n" not in str(err.value)


def test_the_section_must_be_a_mapping_of_at_most_max_cues() -> None:
    with pytest.raises(ConfigError, match="must be a mapping"):
        from_dict({"cues": ["spring"]})
    with pytest.raises(ConfigError, match="more than"):
        from_dict({"cues": {f"s{i}": {"type": "spring"} for i in range(10)}})


def test_the_section_round_trips_through_a_mapping() -> None:
    cfg = from_dict({"cues": {"tracking": {"enabled": False}, "left": {"type": "spring", "stiffness": 12.5}}})
    assert from_dict(to_dict(cfg)) == cfg


def test_replace_changes_one_cue() -> None:
    cfg = load().replace(cues={"viscous": {"enabled": False}})
    assert cfg.cue("viscous") is None and cfg.cue("tracking") is not None
