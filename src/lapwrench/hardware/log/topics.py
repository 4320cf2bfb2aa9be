"""The log's topics and the JSON schemas of its JSON channels (see the package docstring)."""

from __future__ import annotations

from typing import Any

CYCLE_TOPIC = "/lapwrench/cycle"
EVENT_TOPIC = "/lapwrench/event"
META_TOPIC = "/lapwrench/meta"
STATS_TOPIC = "/lapwrench/log_stats"
LOG_TOPIC = "/lapwrench/log"
TF_TOPIC = "/lapwrench/tf"
POSE_TOPIC = "/lapwrench/scope_pose"
JOINTS_TOPIC = "/lapwrench/joint_states"
WRENCH_TOPIC = "/lapwrench/wrenches"
IMAGE_TOPIC = "/lapwrench/camera/image"

EVENT_SCHEMA: dict[str, Any] = {
    "title": "lapwrench.Event",
    "type": "object",
    "properties": {"time": {"type": "number"}, "kind": {"type": "string"}, "message": {"type": "string"}},
}
META_SCHEMA: dict[str, Any] = {"title": "lapwrench.Meta", "type": "object"}
STATS_SCHEMA: dict[str, Any] = {
    "title": "lapwrench.LogStats",
    "type": "object",
    "properties": {
        k: {"type": "integer"}
        for k in ("cycles", "dropped", "events", "dropped_events", "images", "dropped_images", "transforms", "errors",
                  "bad_times")
    }
    | {
        "first_error": {"type": ["string", "null"]},
        "first_bad_time": {"type": ["string", "null"]},
        "capacity": {"type": "integer"},
        "transform_rate_hz": {"type": "number"},
    },
}
