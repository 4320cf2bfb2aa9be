"""The ``cues:`` section of the configuration: which cues run, and each one's validated parameters.

Each key names one cue: the name of its wrench in the logs, plots and telemetry. Its value is a
mapping with an optional ``type`` (the registered cue, :mod:`lapwrench.plugins`; by default the
key itself), ``enabled`` (default true) and the cue's own parameters, range-checked against its
``Params`` dataclass like every other section::

    cues:
      keep_out:                 # type defaults to the key
        center: [0.45, 0.0, 0.05]
        radius: 0.04
      tracking: {enabled: false}

The paper's four cues (``rcm``, ``interaction``, ``tracking``, ``viscous``) are on unless a file
switches one off; their parameters stay in their own sections (``tracking:``, ...). ``rcm`` is
the primary task and cannot be switched off.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from lapwrench import plugins
from lapwrench.config_ranges import ConfigError, build
from lapwrench.config_yaml import cut, short

PAPER_CUES = ("rcm", "interaction", "tracking", "viscous")
PRIMARY = "rcm"
MAX_CUES = 8  # the real-time bus carries at most 8 wrenches a cycle (hardware.rt.codec: N_WRENCH)
MAX_CUE_TELEMETRY = 8  # telemetry fields one cue may declare (each is logged every cycle)
MAX_TELEMETRY = 24  # telemetry fields of the running Python cues together (a real-time bus row holds that many)
_RESERVED = ("type", "enabled")


def _show(key: Any) -> str:
    """A user's key as one short line of text (escaped control characters, at most 40 characters)."""
    return cut(str(key).encode("unicode_escape").decode("ascii"), 40)


@dataclass(frozen=True)
class CueEntry:
    """One cue of the ``cues:`` section: its name, its registered type, whether it runs, and its
    parameters (an instance of the cue class's ``Params``; None for the paper's cues, which read
    their own sections, and for cues without parameters)."""

    name: str
    type: str
    enabled: bool = True
    params: Any = None


DEFAULT_CUES: tuple[CueEntry, ...] = tuple(CueEntry(n, n) for n in PAPER_CUES)


def _entry(name: str, data: Any) -> tuple[CueEntry, int]:
    """One cue of the section, and the number of telemetry fields it logs (none for the compiled
    tick's cues: they run outside the Python cues' telemetry)."""
    key = f"cues.{name}"
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"config section '{key}' must be a mapping, got {type(data).__name__}", key)
    kind = data.get("type", name)
    if not isinstance(kind, str) or not plugins.NAME.match(kind):
        raise ConfigError(f"config key '{key}.type' must be a cue name, got {short(kind)}", f"{key}.type")
    enabled = data.get("enabled", True)
    if not isinstance(enabled, bool):
        raise ConfigError(f"config key '{key}.enabled' must be true or false, got {short(enabled)}", f"{key}.enabled")
    if name == PRIMARY and (not enabled or kind != PRIMARY):
        raise ConfigError(f"config key '{key}' is the primary task (the RCM) and cannot be switched off or replaced",
                          key)
    try:
        cls = plugins.load(plugins.CUE_GROUP, kind)
    except plugins.PluginError as exc:
        raise ConfigError(f"config key '{key}': {exc}", key) from exc
    if getattr(cls, "fused", False) and name != kind:
        raise ConfigError(f"config key '{key}.type': cue '{kind}' is part of the compiled tick and runs only under "
                          f"its own name ('{kind}')", f"{key}.type")
    n_telemetry = 0 if getattr(cls, "fused", False) else len(telemetry_fields(cls, key, kind))
    values = {k: v for k, v in data.items() if k not in _RESERVED}
    section = getattr(cls, "config_section", None)
    params_cls = getattr(cls, "Params", None)
    if section is not None or params_cls is None:
        if values:
            where = f"in the '{section}:' section" if section else "none"
            first = _show(next(iter(values)))
            raise ConfigError(f"config key '{key}.{first}': cue '{kind}' takes no parameters here "
                              f"(its parameters: {where})", f"{key}.{first}")
        return CueEntry(name, kind, enabled), n_telemetry
    try:
        params = build(params_cls, values, key)
    except ConfigError as exc:  # raised by the plugin's own checks (Params.__post_init__): name the cue
        if exc.key is not None and exc.key.startswith(f"{key}."):
            raise
        sub = f"{key}.{exc.key}" if exc.key else key
        raise ConfigError(f"config key '{sub}': {exc}", sub) from exc
    return CueEntry(name, kind, enabled, params), n_telemetry


def parse_cues(data: Any) -> tuple[CueEntry, ...]:
    """The ``cues:`` section as entries: the paper's four first (in the paper's order, unless the
    file switches them off), then the file's other cues in file order."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"config section 'cues' must be a mapping, got {type(data).__name__}", "cues")
    for name in data:
        if not isinstance(name, str) or not plugins.NAME.match(name):
            raise ConfigError(f"config key 'cues.{_show(name)}': a cue name is a lower-case identifier "
                              "(a-z, 0-9, _; at most 40 characters)", "cues")
    if len(set(data) | set(PAPER_CUES)) > MAX_CUES:
        raise ConfigError(f"config section 'cues' has more than {MAX_CUES} cues", "cues")
    names = list(PAPER_CUES) + [n for n in data if n not in PAPER_CUES]
    parsed = [_entry(n, data.get(n)) for n in names]
    total = sum(n for e, n in parsed if e.enabled)
    if total > MAX_TELEMETRY:
        raise ConfigError(f"config section 'cues': the cues that run declare {total} telemetry fields together; "
                          f"at most {MAX_TELEMETRY} are logged each cycle", "cues")
    return tuple(e for e, _ in parsed)


def telemetry_fields(cls: Any, key: str, kind: str) -> tuple[str, ...]:
    """The ``telemetry_fields`` of cue class ``cls`` (configured at ``key``), checked by
    :func:`telemetry_fields_problem`, else a :class:`ConfigError`."""
    fields = getattr(cls, "telemetry_fields", ())
    problem = telemetry_fields_problem(fields)
    if problem:
        raise ConfigError(f"config key '{key}': cue '{kind}' {problem}", key)
    return tuple(fields)


def telemetry_fields_problem(fields: object) -> str:
    """What is wrong with a cue's telemetry field names ("" when nothing): they must be at most
    :data:`MAX_CUE_TELEMETRY` distinct lower-case names (each becomes a field of the log's cycle message
    and a column of the traces). The configuration and a log layout given in code both check with it."""
    if not isinstance(fields, tuple | list) or not all(isinstance(f, str) and plugins.NAME.match(f) for f in fields):
        return (f"has telemetry_fields {short(fields)}; they must be a tuple of lower-case names (a-z, 0-9, _; "
                "at most 40 characters)")
    if len(set(fields)) != len(fields):
        return f"names a telemetry field twice: {short(tuple(fields))}"
    if len(fields) > MAX_CUE_TELEMETRY:
        return f"declares {len(fields)} telemetry fields; a cue logs at most {MAX_CUE_TELEMETRY}"
    return ""


def cues_to_dict(entries: tuple[CueEntry, ...]) -> dict[str, Any]:
    """The entries as the YAML mapping :func:`parse_cues` reads back."""
    out: dict[str, Any] = {}
    for e in entries:
        d: dict[str, Any] = {} if e.type == e.name else {"type": e.type}
        if not e.enabled:
            d["enabled"] = False
        if e.params is not None:
            d.update({k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(e.params).items()})
        out[e.name] = d
    return out
