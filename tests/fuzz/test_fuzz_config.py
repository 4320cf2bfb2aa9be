"""Fuzzing the config loader (issue 11, item 11): any input gives a Config or a short ConfigError.

Properties, each over the fixed-seed profile of ``conftest.py``:

* arbitrary bytes, and YAML-like text assembled from the config's own names and YAML's syntax
  (anchors, aliases, tags, merge keys, flow and block collections), written to a file: ``load``
  returns a :class:`Config` or raises :class:`ConfigError`, never anything else, with a one-line
  message under 500 characters;
* random trees over the real section and key names, and the default config with one key set to a
  random value (NaN, inf, huge ints, long strings, lists, mappings, ...): ``from_dict`` likewise;
* any Config that loads has every number finite and inside its documented range, and survives a
  dump/load round trip unchanged.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from pathlib import Path
from typing import Any

import pytest
from hypothesis import event, given
from hypothesis import strategies as st

from lapwrench import config
from lapwrench.config import Config, ConfigError, dump, from_dict, load, to_dict

DEFAULTS = {k: v for k, v in to_dict(Config()).items() if k != "cues"}  # cues: its own parser and fuzz below
SECTIONS = sorted(DEFAULTS)
KEYS = sorted({k for section in DEFAULTS.values() for k in section})
MAX_MESSAGE = 500
CHARS = st.characters()  # any code point, surrogates too; st.text()'s default utf-8 codec costs seconds to set up


def _leaves(cfg: Config) -> list[tuple[str, dataclasses.Field, Any]]:
    """(key path, field, value) of every value in ``cfg``."""
    out = []
    for section, cls in typing.get_type_hints(Config).items():
        if not dataclasses.is_dataclass(cls):
            continue  # the cues: section (its own parser; tests/test_config_cues.py)
        part = getattr(cfg, section)
        out += [(f"{section}.{f.name}", f, getattr(part, f.name)) for f in dataclasses.fields(cls)]
    return out


def _assert_sane(cfg: Config) -> None:
    for key, f, value in _leaves(cfg):
        values = value if isinstance(value, tuple) else (value,)  # a vector's range holds for each element
        for v in values:
            if isinstance(v, float):
                assert math.isfinite(v), key
        bounds = f.metadata.get("range")
        if bounds is not None:
            assert all(v in bounds for v in values), (key, value)


def _assert_short(err: ConfigError) -> None:
    text = str(err)
    assert len(text) < MAX_MESSAGE, text[:200]
    assert "\n" not in text


def _outcome(build: typing.Callable[[], Config]) -> Config | None:
    """``build()``'s Config, or None after checking its ConfigError; any other exception fails the test."""
    try:
        cfg = build()
    except ConfigError as err:
        _assert_short(err)
        event("ConfigError")
        return None
    _assert_sane(cfg)
    event("Config")
    return cfg


huge_ints = st.sampled_from([10**400, -(10**400), 2**64, -(2**63), 10**19])
numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**6), max_value=10**6),
    huge_ints,
    st.sampled_from([0, 1, 63, 64, 255, 256, 1000, 0.0, -0.0, 1e-300, 1e300, 5e-324, math.pi]),
)
scalars = st.one_of(
    numbers,
    st.booleans(),
    st.none(),
    st.text(CHARS, max_size=30),
    st.sampled_from(["AA55", "zz", "", "c1", "none", "speed", "panda", "crc16-modbus", "1e3", "x" * 100_000]),
)
key_names = st.sampled_from(KEYS) | st.text(CHARS, max_size=8)
values = st.recursive(
    scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(key_names, inner, max_size=4)),
    max_leaves=8,
)
sections = st.dictionaries(key_names, values, max_size=6)
trees = st.dictionaries(st.sampled_from(SECTIONS) | st.text(CHARS, max_size=8), sections | values, max_size=5)


@given(trees)
def test_random_trees_give_a_config_or_a_short_config_error(tree: dict[str, Any]) -> None:
    _outcome(lambda: from_dict(tree))


cue_names = st.sampled_from(["rcm", "interaction", "tracking", "viscous", "zoom", "keep_out", "x"]) | st.text(
    CHARS, max_size=8
)
cue_keys = st.sampled_from(["type", "enabled", "radius", "center", "shape", "band", "gain", "F_max"]) | key_names
cue_entries = st.none() | values | st.dictionaries(cue_keys, values | cue_names, max_size=5)


@given(st.dictionaries(cue_names, cue_entries, max_size=6) | values)
def test_random_cues_sections_give_a_config_or_a_short_config_error(cues: Any) -> None:
    cfg = _outcome(lambda: from_dict({"cues": cues}))
    if cfg is not None:
        assert cfg.cue("rcm") is not None  # the primary task always runs
        assert from_dict(to_dict(cfg)) == cfg


@given(st.sampled_from([(s, k) for s in SECTIONS for k in DEFAULTS[s]]), values)
def test_one_key_of_the_defaults_set_to_anything(where: tuple[str, str], value: Any) -> None:
    section, key = where
    data = to_dict(Config())
    data[section][key] = value
    cfg = _outcome(lambda: from_dict(data))
    if cfg is not None:  # whatever was accepted is that value, as the field's type
        assert getattr(getattr(cfg, section), key) == value


NUMERIC_KEYS = [(s, k) for s in SECTIONS for k, v in DEFAULTS[s].items() if type(v) in (int, float)]


@st.composite
def numeric_mutations(draw: st.DrawFn) -> tuple[str, str, float]:
    """A numeric key and a new value: anywhere in ±1e6, or 0-3x its default (mostly accepted)."""
    section, key = draw(st.sampled_from(NUMERIC_KEYS))
    default = DEFAULTS[section][key]
    value = draw(st.floats(min_value=-1e6, max_value=1e6) | st.floats(0.0, 3.0).map(lambda f: default * f))
    return section, key, round(value) if isinstance(default, int) else value


@given(numeric_mutations())
def test_accepted_numbers_round_trip_through_a_file(
    tmp_path_factory: pytest.TempPathFactory, mutation: tuple[str, str, float]
) -> None:
    section, key, value = mutation
    data = to_dict(Config())
    data[section][key] = value
    cfg = _outcome(lambda: from_dict(data))
    if cfg is not None:
        path = tmp_path_factory.getbasetemp() / "round-trip.yaml"
        dump(cfg, path)
        assert load(path) == cfg


def _load_bytes(raw: bytes, tmp_path_factory: pytest.TempPathFactory) -> None:
    path: Path = tmp_path_factory.getbasetemp() / "fuzz.yaml"
    path.write_bytes(raw)
    _outcome(lambda: load(path))


@given(st.binary(max_size=2000))
def test_arbitrary_bytes_give_a_config_or_a_short_config_error(
    tmp_path_factory: pytest.TempPathFactory, raw: bytes
) -> None:
    _load_bytes(raw, tmp_path_factory)


_SYNTAX = [
    ":", ": ", "\n", "\n  ", "\n    ", "- ", "[", "]", "{", "}", ", ", "&a ", "*a", "&b ", "*b", "<<: ", "!!str ",
    "!!python/object:os.system ", "!!binary ", "!foo ", "? ", "# c", "---\n", "...\n", "'", '"', "|\n  ", ">\n  ",
    "\t", "\x00", "\ufeff", "1e400", "9" * 400, ".nan", ".inf", "-.inf", "0x1F", "0o17", "1_000", "1:30",
    "2001-02-30", "~", "null", "yes", "no", "true", "AA55", "crc16-modbus", "c1", "speed", "x" * 200,
]
yaml_tokens = st.sampled_from(_SYNTAX + SECTIONS + KEYS) | st.text(CHARS, max_size=6) | numbers.map(str)


@given(st.lists(yaml_tokens, max_size=40))
def test_yaml_like_text_gives_a_config_or_a_short_config_error(
    tmp_path_factory: pytest.TempPathFactory, tokens: list[str]
) -> None:
    _load_bytes("".join(tokens).encode("utf-8", "surrogatepass"), tmp_path_factory)


@given(
    st.lists(
        st.tuples(st.sampled_from(SECTIONS), st.lists(st.tuples(st.sampled_from(KEYS), yaml_tokens), max_size=4)),
        max_size=5,
    )
)
def test_block_yaml_over_the_real_names_gives_a_config_or_a_short_config_error(
    tmp_path_factory: pytest.TempPathFactory, body: list[tuple[str, list[tuple[str, str]]]]
) -> None:
    text = "".join(f"{s}:\n" + "".join(f"  {k}: {v}\n" for k, v in items) for s, items in body)
    _load_bytes(text.encode("utf-8", "surrogatepass"), tmp_path_factory)


def test_the_fuzzed_names_are_the_real_ones() -> None:
    """Guards the strategies above: they draw from every section of the real Config."""
    assert set(SECTIONS) | {"cues"} == {f.name for f in dataclasses.fields(Config)}
    assert "tactile" in SECTIONS and "Kd" in KEYS
    assert config.load() == Config()
