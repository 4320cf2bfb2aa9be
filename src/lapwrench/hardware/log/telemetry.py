"""The cues' telemetry in the cycle message: which cues log which fields (a :data:`TelemetryLayout`),
and the ``lapwrench.Telemetry`` part of the cycle schema built from it.

Every cue declares ``telemetry_fields`` and returns one number per field each tick
(:meth:`lapwrench.wrenches.base.Cue.telemetry`); the controller hands the Python cues' values over
in :attr:`TickResult.telemetry <lapwrench.controller.TickResult.telemetry>`, by cue name. The log
declares one message per cue, with one ``double`` per field, so Foxglove plots them by name:
``/lapwrench/cycle.telemetry.zoom.spread``. The paper's cues run inside the compiled tick and report
nothing there (the interaction cue's δ and contact count are the cycle's ``delta`` and ``contacts``).

Sizes are bounded where the configuration is read (:data:`~lapwrench.config_cues.MAX_CUE_TELEMETRY`
fields a cue, :data:`~lapwrench.config_cues.MAX_TELEMETRY` in all), and again by
:func:`checked_layout` for a layout given in code.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from lapwrench import plugins
from lapwrench.config_cues import MAX_TELEMETRY, CueEntry, parse_cues, telemetry_fields_problem
from lapwrench.config_ranges import ConfigError

if TYPE_CHECKING:
    from google.protobuf.descriptor_pb2 import FileDescriptorProto

TelemetryLayout = tuple[tuple[str, tuple[str, ...]], ...]
"""(cue name, its telemetry field names) for each cue whose telemetry the log carries, in order."""

TELEMETRY_MESSAGE = "Telemetry"
TELEMETRY_FIELD = "telemetry"


def checked_layout(telemetry: Mapping[str, Sequence[str]] | Iterable[tuple[str, Sequence[str]]]) -> TelemetryLayout:
    """``telemetry`` (cue name → field names) as a layout, or ValueError when a name is not a
    lower-case identifier, a name repeats, or the sizes pass the configuration's bounds."""
    items = list(telemetry.items() if isinstance(telemetry, Mapping) else telemetry)
    layout = tuple((str(cue), tuple(str(f) for f in fields)) for cue, fields in items if fields)
    names = [cue for cue, _ in layout]
    if len(set(names)) != len(names):
        raise ValueError(f"cue telemetry: a cue is named twice in {names}")
    for cue, fields in layout:
        if not plugins.NAME.match(cue):
            raise ValueError(f"cue telemetry: {cue!r} is not a lower-case name (a-z, 0-9, _)")
        problem = telemetry_fields_problem(fields)
        if problem:
            raise ValueError(f"cue telemetry of {cue!r}: {problem}")
    total = sum(len(f) for _, f in layout)
    if total > MAX_TELEMETRY:
        raise ValueError(f"cue telemetry: {total} fields in all; at most {MAX_TELEMETRY} are logged")
    return layout


def _declared_fields(cls: object) -> Any:
    """The telemetry field names a cue type declares, as declared; () for a type fused into the compiled
    tick (it logs none there)."""
    return () if getattr(cls, "fused", False) else getattr(cls, "telemetry_fields", ())


def telemetry_layout(cues: Iterable[CueEntry]) -> TelemetryLayout:
    """The layout of a configuration's cues (``cfg.cues``): each enabled cue that runs in Python
    (not ``fused`` into the compiled tick) and declares telemetry fields, in configuration order."""
    out = []
    for entry in cues:
        if not entry.enabled:
            continue
        cls = plugins.load(plugins.CUE_GROUP, entry.type)
        fields = tuple(_declared_fields(cls))
        if fields:
            out.append((entry.name, fields))
    return checked_layout(out)


def simulation_layout(*configs: Iterable[CueEntry]) -> TelemetryLayout:
    """The layout of live simulated runs (``demo --foxglove``, ``ui --foxglove``), whose scenarios
    and page may add cues the configuration does not name: the layout of the first configuration's
    cues (``cfg.cues``, bounded where it was read), the cues of the others, then every registered cue
    type (:func:`lapwrench.plugins.names`, in name order) that runs in Python and declares telemetry
    fields, under its type name (how the scenarios add one: ``cues={"zoom": {}}``). A name already
    present is skipped, and so is a type that fails to load or whose names break the bounds; the
    additions stop before :data:`~lapwrench.config_cues.MAX_TELEMETRY` fields would be passed."""
    first, *others = configs or ((),)
    out = list(telemetry_layout(first))
    total = sum(len(f) for _, f in out)

    def candidates() -> Iterator[tuple[str, tuple[str, ...]]]:
        for cues in others:
            yield from telemetry_layout(cues)
        for name in plugins.names(plugins.CUE_GROUP):
            try:
                cls = plugins.load(plugins.CUE_GROUP, name)
            except plugins.PluginError:
                continue
            fields = _declared_fields(cls)
            if plugins.NAME.match(name) and not telemetry_fields_problem(fields):
                yield name, tuple(fields)

    for name, fields in candidates():
        if not fields or any(name == n for n, _ in out):
            continue
        if total + len(fields) > MAX_TELEMETRY:
            break
        out.append((name, fields))
        total += len(fields)
    return checked_layout(out)


def layout_from_meta(meta: Mapping[str, Any] | None) -> TelemetryLayout:
    """The layout of the configuration a run's meta message carries (``meta["config"]``, as
    :func:`lapwrench.config.to_dict` gives it); empty without one, or when its cues no longer load."""
    config = None if meta is None else meta.get("config")
    if not isinstance(config, Mapping):
        return ()
    try:
        return telemetry_layout(parse_cues(config.get("cues")))
    except (ConfigError, plugins.PluginError, ValueError):
        return ()


def message_name(cue: str) -> str:
    """The nested message type of a cue's fields in ``lapwrench.Telemetry`` (the cue name with a
    capital first letter: distinct from the field that holds it, and one type per cue name)."""
    return cue[:1].upper() + cue[1:]


def add_telemetry_message(file: FileDescriptorProto, layout: TelemetryLayout) -> str:
    """Add ``lapwrench.Telemetry`` to ``file``: one optional message field per cue (field numbers
    1, 2, ... in layout order), each with a ``double`` per telemetry field. Returns its full name."""
    from google.protobuf.descriptor_pb2 import FieldDescriptorProto as F

    telemetry = file.message_type.add(name=TELEMETRY_MESSAGE)
    for i, (cue, fields) in enumerate(layout, start=1):
        nested = telemetry.nested_type.add(name=message_name(cue))
        for j, name in enumerate(fields, start=1):
            nested.field.add(name=name, number=j, label=F.LABEL_OPTIONAL, type=F.TYPE_DOUBLE)
        full = f".{file.package}.{TELEMETRY_MESSAGE}.{message_name(cue)}"
        telemetry.field.add(name=cue, number=i, label=F.LABEL_OPTIONAL, type=F.TYPE_MESSAGE, type_name=full)
    return f".{file.package}.{TELEMETRY_MESSAGE}"
