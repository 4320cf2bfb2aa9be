"""lapwrench.hardware.log.topics: the log's topics and the JSON schemas of its JSON channels, which
Foxglove shows the messages with (they must describe what the logger writes)."""

from __future__ import annotations

from pathlib import Path

from lapwrench.hardware.log import RunLogger, log_topics, topics


def test_every_topic_is_its_own_and_under_lapwrench() -> None:
    names = [getattr(topics, n) for n in dir(topics) if n.endswith("_TOPIC")]
    assert len(names) == 10 and len(set(names)) == len(names)
    assert all(t.startswith("/lapwrench/") for t in names)


def test_the_stats_schema_describes_every_counter_the_logger_writes(tmp_path: Path) -> None:
    logger = RunLogger(tmp_path / "run.mcap", {"robot": "test"})
    logger.close()
    stats = logger.stats()
    props = topics.STATS_SCHEMA["properties"]
    assert set(stats) == set(props)
    for key, value in stats.items():
        kind = props[key]["type"]
        expected = {"integer": int, "number": (int, float)}.get(kind) if isinstance(kind, str) else (str, type(None))
        assert isinstance(value, expected), (key, value, kind)  # type: ignore[arg-type]


def test_the_json_channels_carry_their_schema_titles(tmp_path: Path) -> None:
    with RunLogger(tmp_path / "run.mcap", {"robot": "test"}) as logger:
        logger.event(0.0, "start", "go")
    found = log_topics(tmp_path / "run.mcap")
    for topic, schema in ((topics.EVENT_TOPIC, topics.EVENT_SCHEMA), (topics.META_TOPIC, topics.META_SCHEMA),
                          (topics.STATS_TOPIC, topics.STATS_SCHEMA)):
        assert found[topic].schema == schema["title"] and found[topic].encoding == "json"
    assert set(topics.EVENT_SCHEMA["properties"]) == {"time", "kind", "message"}
