"""Building the cues a configuration names (its ``cues:`` section, :mod:`lapwrench.config_cues`).

The paper's four cues come out of here like any plugin: looked up by name in the
``lapwrench.cues`` entry-point group and built with their parameters. The controller then runs
the ``fused`` ones inside the compiled tick and the others in Python between its two compiled
stages (:mod:`lapwrench.compiled_tick`).
"""

from __future__ import annotations

from collections.abc import Sequence

from lapwrench import plugins
from lapwrench.config import Config
from lapwrench.config_ranges import ConfigError
from lapwrench.inputs import BUILT_IN_INPUTS, InputSpec
from lapwrench.wrenches.base import Cue


def cue_class(kind: str) -> type[Cue]:
    """The registered cue class ``kind`` (ConfigError when it is unknown or not a :class:`Cue`)."""
    try:
        cls = plugins.load(plugins.CUE_GROUP, kind)
    except plugins.PluginError as exc:
        raise ConfigError(str(exc), "cues") from exc
    if not (isinstance(cls, type) and issubclass(cls, Cue)):
        raise ConfigError(f"cue {kind!r} is registered as {cls!r}, which is not a lapwrench Cue class", "cues")
    if cls.priority not in ("task", "null"):
        raise ConfigError(f"cue {kind!r} has priority {cls.priority!r}; it must be 'task' or 'null'", "cues")
    return cls


def build_cues(cfg: Config) -> list[Cue]:
    """One :class:`Cue` per enabled entry of ``cfg.cues``, in its order."""
    cues: list[Cue] = []
    for entry in cfg.cues:
        if not entry.enabled:
            continue
        cls = cue_class(entry.type)
        params = getattr(cfg, cls.config_section) if cls.config_section else entry.params
        cues.append(cls(entry.name, params, cfg))
    input_specs(cues)  # every input a cue asks for is known
    return cues


def input_specs(cues: Sequence[Cue]) -> dict[str, InputSpec]:
    """The registered inputs the cues ask for beyond the built-in ones, by name (ConfigError for an
    input that is not registered)."""
    specs: dict[str, InputSpec] = {}
    for cue in cues:
        for name in cue.inputs:
            if name in BUILT_IN_INPUTS or name in specs:
                continue
            try:
                spec = plugins.load(plugins.INPUT_GROUP, name)
            except plugins.PluginError as exc:
                raise ConfigError(f"cue {cue.name!r} needs input {name!r}: {exc}", f"cues.{cue.name}") from exc
            if not isinstance(spec, InputSpec) or spec.name != name:
                raise ConfigError(f"input {name!r} is registered as {spec!r}, not an InputSpec named {name!r}",
                                  f"cues.{cue.name}")
            specs[name] = spec
    return specs
