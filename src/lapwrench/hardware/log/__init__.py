"""Run logs in MCAP, written through foxglove-sdk: Foxglove, the ``mcap`` CLI and Python open them.

Topics
------
Foxglove's standard schemas (``foxglove.*``, protobuf) wherever one fits, so Foxglove's 3D,
Image, Log and Plot panels show them as they are; compact custom messages (``lapwrench.*``) for
the rest: the 1 kHz cycle in protobuf (encoded and decoded by the ``google.protobuf`` library
from a ``FileDescriptorProto`` built in :mod:`~lapwrench.hardware.log.cycle_codec`, whose
``FileDescriptorSet`` is the channel's schema; about 1.35 kB a cycle, encoded in ~20-30 µs on the
writer thread, a fifth of what JSON takes), the rare ones in JSON with a JSON schema.
``log_time`` is the session time in ns (``t`` of the cycle; 0 for the meta message). Every
channel lives in a :class:`foxglove.Context` of the logger's own.

``/lapwrench/cycle`` (``lapwrench.Cycle``, protobuf, every control cycle, 1 kHz)
    time, robot time, measured q/dq/tau_J/external force, the inputs the loop used (F/T force
    and torque, the 64 tactile values, instrument image points with ``instrument_count``; an
    absent or stale input is an empty field, -1 points), each wrench ``[moment; force]`` in {B}
    (repeated ``lapwrench.Wrench {name, w}``), the mode, grip gain, the RCM point p_R, the
    closest point p_G (empty when not given), the RCM error vector and norm (at the reference)
    and the RCM error of the *measured* joints (NaN when unknown), the controller's command, the
    command actually sent, supervisor state/alarm, compute and cycle times, and the cues'
    telemetry: ``telemetry.<cue>.<field>`` (a message per cue that runs in Python and declares
    ``telemetry_fields``, a ``double`` per field; the schema is built from the configured cues,
    :mod:`~lapwrench.hardware.log.telemetry`). Field numbers: :data:`CYCLE_FIELDS`.
``/lapwrench/event`` (``lapwrench.Event``, JSON)
    supervisor and input events: ``{time, kind, message}``.
``/lapwrench/meta`` (``lapwrench.Meta``, JSON)
    one message at the start: configuration, robot, devices, command line.
``/lapwrench/log_stats`` (``lapwrench.LogStats``, JSON; also an MCAP metadata record)
    one message at close: messages written and **dropped** by the logger (see below), writer
    errors. A ``log_dropped`` event is added on ``/lapwrench/event`` when anything was dropped.
``/lapwrench/log`` (``foxglove.Log``)
    the events again, for Foxglove's Log panel (``error`` kinds at level ERROR, ``start``,
    ``stop`` and ``input_fresh`` at INFO, the rest at WARNING).
``/lapwrench/tf`` (``foxglove.FrameTransforms``, 100 Hz by default, needs ``model``)
    the arm's link frames as a tree (each URDF body frame in its parent body frame, root = the
    base link, e.g. ``panda_link0``) with the scope frames of the paper: E = ``lap_E`` (scope
    flange), H = ``lap_H`` (handle), C = ``lap_C`` (camera), from the measured q; and
    R = ``lap_R`` (the RCM point p_R) and G = ``lap_G`` (the closest point p_G, when the record
    has it) in the base frame, with the scope's orientation R_E (their z is the shaft axis).
    The joint-driven links, R and G are in every set; the frames fixed to their parent (the
    flange, E on it, H, C and the other scope frames on E) in the first set and every 100th (1 Hz).
``/lapwrench/scope_pose`` (``foxglove.PoseInFrame``, same rate, needs ``model``)
    pose of E in the base frame.
``/lapwrench/joint_states`` (``foxglove.JointStates``, same rate)
    measured joint positions, velocities and torques (tau_J).
``/lapwrench/wrenches`` (``foxglove.SceneUpdate``, same rate, needs ``model``)
    one entity per wrench (id = its name) with one arrow along its *force*, 1 cm per N, drawn
    at the point where the force acts: ``rcm`` at R, ``interaction`` at H, the other
    null-space wrenches at G (E when the record has no p_G). The moments are in the cycle message.
``/lapwrench/camera/image`` (``foxglove.CompressedImage``, as given to :meth:`RunLogger.image`)
    laparoscope frames in ``lap_C``: JPEG bytes as they are, or RGB/grey arrays JPEG-encoded on
    the writer thread (OpenCV releases the GIL while encoding).

Writing never blocks the control loop
-------------------------------------
:meth:`RunLogger.cycle` appends the record (references to the loop's arrays: the loop must not
change them afterwards) to a bounded ring of ``capacity`` records (4096 by default, 4 s at
1 kHz) and returns, in about 1 µs (``bench/log.py``). When the ring is full the record is
dropped and counted (:attr:`RunLogger.dropped`); the log never grows without bound. Events and
images have rings of their own (1024 and 4), with their own drop counters.

The writer thread encodes the records and, at ``transform_rate_hz`` of session time (downsampled
from the cycles), computes the frames: forward kinematics of the *logged measured* q on a
Pinocchio workspace of its own, never in the loop. It shares the interpreter with the 1 kHz
loop, so it holds the GIL in short rounds and sleeps in between, which hands the GIL back: a
round is at most ``WRITE_BUDGET_S`` (150 µs) of cycles plus the one in hand, or one of the two
steps of a frame set alone; it sleeps ``PAUSE_BUSY_S`` (300 µs) between rounds while work
waits and ``PAUSE_IDLE_S`` (1 ms) when there is none. foxglove-sdk buffers and
zstd-compresses 1 MB chunks in native code.

Reading
-------
:func:`read_log` gives ``(cycles, events, meta)`` as dicts (a cycle as
:meth:`CycleRecord.to_dict`: lists, NaN and absent values as ``None``); :func:`load_log` adds
the log stats and the topics with their schema names and message counts; :func:`iter_messages`
decodes any message (JSON, so the logs of the earlier JSON-only logger too; the cycle with
:func:`decode_cycle`; Foxglove's protobuf messages through the schemas in the file). A missing,
corrupt or foreign file raises :class:`LogFileError` with a plain message, which
:func:`log_report_main` (``lapwrench log-report``: PNG plots of RCM error, wrenches, mode and
joint commands, summary.json with the logger's drop counts) prints instead of a traceback. A
truncated file (no closing magic: the run was killed) is refused by :func:`read_log`; ``load_log(path,
allow_truncated=True)`` and ``lapwrench log-report`` read it as far as it goes with mcap's stream
reader (whole, CRC-checked chunks only) and say so (:class:`Truncation`).

Modules
-------
:mod:`~lapwrench.hardware.log.record` (:class:`CycleRecord`),
:mod:`~lapwrench.hardware.log.topics` (topics, JSON schemas),
:mod:`~lapwrench.hardware.log.cycle_codec` (the ``lapwrench.Cycle`` schema, encode/decode),
:mod:`~lapwrench.hardware.log.telemetry` (the cues' telemetry in it),
:mod:`~lapwrench.hardware.log.frames` (forward kinematics of the logged q),
:mod:`~lapwrench.hardware.log.messages` (Foxglove's messages), :mod:`~lapwrench.hardware.log.sink`
(the MCAP file and its channels), :mod:`~lapwrench.hardware.log.writer` (:class:`RunLogger`),
:mod:`~lapwrench.hardware.log.reader` and :mod:`~lapwrench.hardware.log.report`.
"""

from __future__ import annotations

from lapwrench.hardware.log.cycle_codec import (
    CYCLE_FIELDS,
    CYCLE_SCHEMA_NAME,
    INSTRUMENT_COUNT_FIELD,
    TELEMETRY_FIELD_NUMBER,
    cycle_descriptor,
    decode_cycle,
    encode_cycle,
)
from lapwrench.hardware.log.frames import (
    FRAME_G,
    FRAME_R,
    FrameSolver,
    Placement,
    ScopeFrames,
)
from lapwrench.hardware.log.messages import (
    ARROW_M_PER_N,
    JPEG_QUALITY,
    encode_jpeg,
    frame_transforms_message,
    image_message,
    joint_states_message,
    pose_message,
    wrench_scene_message,
)
from lapwrench.hardware.log.reader import (
    LogContents,
    LogFileError,
    TopicInfo,
    Truncation,
    check_log_file,
    iter_messages,
    load_log,
    log_topics,
    read_log,
)
from lapwrench.hardware.log.record import (
    CycleRecord,
)
from lapwrench.hardware.log.report import (
    add_log_report_arguments,
    log_report_main,
    make_report,
    truncation_note,
    write_report,
)
from lapwrench.hardware.log.telemetry import (
    TelemetryLayout,
    checked_layout,
    telemetry_layout,
)
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
from lapwrench.hardware.log.writer import (
    CYCLE_CAPACITY,
    EVENT_CAPACITY,
    IMAGE_CAPACITY,
    PAUSE_BUSY_S,
    PAUSE_IDLE_S,
    STATIC_EVERY,
    TRANSFORM_RATE_HZ,
    WRITE_BUDGET_S,
    LogCounters,
    RunLogger,
)

__all__ = [
    "ARROW_M_PER_N",
    "CYCLE_CAPACITY",
    "CYCLE_FIELDS",
    "CYCLE_SCHEMA_NAME",
    "CYCLE_TOPIC",
    "EVENT_CAPACITY",
    "EVENT_SCHEMA",
    "EVENT_TOPIC",
    "FRAME_G",
    "FRAME_R",
    "IMAGE_CAPACITY",
    "IMAGE_TOPIC",
    "INSTRUMENT_COUNT_FIELD",
    "JOINTS_TOPIC",
    "JPEG_QUALITY",
    "LOG_TOPIC",
    "META_SCHEMA",
    "META_TOPIC",
    "PAUSE_BUSY_S",
    "PAUSE_IDLE_S",
    "POSE_TOPIC",
    "STATIC_EVERY",
    "STATS_SCHEMA",
    "STATS_TOPIC",
    "TELEMETRY_FIELD_NUMBER",
    "TF_TOPIC",
    "TRANSFORM_RATE_HZ",
    "WRENCH_TOPIC",
    "WRITE_BUDGET_S",
    "CycleRecord",
    "FrameSolver",
    "LogContents",
    "LogCounters",
    "LogFileError",
    "Placement",
    "RunLogger",
    "ScopeFrames",
    "TelemetryLayout",
    "TopicInfo",
    "Truncation",
    "add_log_report_arguments",
    "check_log_file",
    "checked_layout",
    "cycle_descriptor",
    "decode_cycle",
    "encode_cycle",
    "encode_jpeg",
    "frame_transforms_message",
    "image_message",
    "iter_messages",
    "joint_states_message",
    "load_log",
    "log_report_main",
    "log_topics",
    "make_report",
    "pose_message",
    "read_log",
    "telemetry_layout",
    "truncation_note",
    "wrench_scene_message",
    "write_report",
]
