"""The MCAP file: foxglove-sdk's writer and the log's channels, and the JSON payloads."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from lapwrench.hardware.log.cycle_codec import CYCLE_SCHEMA_NAME, cycle_descriptor, cycle_message_classes
from lapwrench.hardware.log.messages import log_level, stamp
from lapwrench.hardware.log.record import plain_list
from lapwrench.hardware.log.telemetry import TelemetryLayout
from lapwrench.hardware.log.topics import (
    CYCLE_TOPIC,
    EVENT_SCHEMA,
    EVENT_TOPIC,
    IMAGE_TOPIC,
    JOINTS_TOPIC,
    LOG_TOPIC,
    META_SCHEMA,
    META_TOPIC,
    POSE_TOPIC,
    STATS_SCHEMA,
    STATS_TOPIC,
    TF_TOPIC,
    WRENCH_TOPIC,
)

MAX_LOG_TIME_S = float(2**32 - 1)
"""The latest log time a message can have, in session seconds (136 years): foxglove's ``Timestamp`` keeps
whole seconds in 32 bits (an MCAP log time, 64-bit ns, would hold 584 years)."""


def log_time_ns(t: object) -> int | None:
    """Session seconds → log time in ns; None for a value that is not a session time (NaN, infinite,
    negative, beyond :data:`MAX_LOG_TIME_S`, not a number): the writer counts it and uses another time."""
    try:
        seconds = float(t)  # type: ignore[arg-type]  # anything: a loop's record is not trusted
    except (TypeError, ValueError, OverflowError):
        return None
    return round(seconds * 1e9) if 0.0 <= seconds <= MAX_LOG_TIME_S else None  # NaN fails the test


def _finite_json(x: Any) -> Any:
    """JSON has no NaN/inf: send them as null (a logged NaN input stays visible as a gap).
    numpy scalars become Python numbers, bools stay bools."""
    if isinstance(x, bool | np.bool_):
        return bool(x)
    if isinstance(x, float | np.floating):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.ndarray):
        return plain_list(x)
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, list | tuple):
        return [_finite_json(v) for v in x]
    if isinstance(x, dict):
        return {str(k): _finite_json(v) for k, v in x.items()}
    return x


def json_bytes(d: Any) -> bytes:
    """Compact JSON bytes; anything non-finite left over becomes null."""
    try:
        return json.dumps(d, separators=(",", ":"), allow_nan=False).encode()
    except (ValueError, TypeError):
        return json.dumps(_finite_json(d), separators=(",", ":"), allow_nan=False, default=str).encode()


class McapSink:
    """The foxglove-sdk MCAP writer and the channels, on a :class:`foxglove.Context` of the
    logger's own (nothing else logged in the process lands in the file, and vice versa).

    Args:
        path: The ``.mcap`` file (replaced if it exists); None: no file (live telemetry only).
        with_frames: Open the transform, pose and wrench-arrow channels (the logger has a model).
        telemetry: The cues whose telemetry the cycle schema declares.
    """

    def __init__(self, path: Path | None, with_frames: bool, telemetry: TelemetryLayout = ()) -> None:
        import foxglove
        from foxglove import channels as fc

        cycle_message_classes(telemetry)  # built here, not with the first cycle on the writer thread
        self.context = foxglove.Context()
        self.writer = None if path is None else foxglove.open_mcap(path, allow_overwrite=True, context=self.context)
        ctx = self.context
        self.json = {
            topic: foxglove.Channel(topic, schema=schema, context=ctx)
            for topic, schema in ((META_TOPIC, META_SCHEMA), (EVENT_TOPIC, EVENT_SCHEMA), (STATS_TOPIC, STATS_SCHEMA))
        }
        schema = foxglove.Schema(name=CYCLE_SCHEMA_NAME, encoding="protobuf", data=cycle_descriptor(telemetry))
        self.cycle = foxglove.Channel(CYCLE_TOPIC, schema=schema, message_encoding="protobuf", context=ctx).base
        self.log = fc.LogChannel(LOG_TOPIC, context=ctx)
        self.joints = fc.JointStatesChannel(JOINTS_TOPIC, context=ctx)
        self.tf = fc.FrameTransformsChannel(TF_TOPIC, context=ctx) if with_frames else None
        self.pose = fc.PoseInFrameChannel(POSE_TOPIC, context=ctx) if with_frames else None
        self.wrenches = fc.SceneUpdateChannel(WRENCH_TOPIC, context=ctx) if with_frames else None
        self._image: Any = None

    def image_channel(self) -> Any:
        """The image channel, created with the first image (no empty topic otherwise)."""
        if self._image is None:
            from foxglove import channels as fc

            self._image = fc.CompressedImageChannel(IMAGE_TOPIC, context=self.context)
        return self._image

    def write_json(self, topic: str, ns: int, payload: bytes) -> None:
        self.json[topic].log(payload, log_time=ns)

    def write_event(self, ns: int, time_s: float, kind: str, message: str) -> None:
        """The event (its time as given, ``time_s``; logged at ``ns``) on ``/lapwrench/event`` and, for
        Foxglove's Log panel, on ``/lapwrench/log``."""
        from foxglove.messages import Log

        self.write_json(EVENT_TOPIC, ns, json_bytes({"time": time_s, "kind": kind, "message": message}))
        self.log.log(Log(timestamp=stamp(ns), level=log_level(kind), message=message, name=kind), log_time=ns)

    def close(self, stats: dict[str, Any]) -> None:
        """The stats as an MCAP metadata record, then the file's summary and footer."""
        if self.writer is not None:
            self.writer.write_metadata("lapwrench.log_stats", {k: str(v) for k, v in stats.items()})
            self.writer.close()
