"""The strict YAML reader of config files: anchors, tags, duplicate keys, size, encoding."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import write_file

from lapwrench import config_yaml
from lapwrench.config import ConfigError, load


def test_an_alias_bomb_is_refused_before_any_expansion(tmp_path: Path) -> None:
    """The 544-byte bomb of the campaign took 55 s and 3 GB; this one is the same shape, 4 levels deep."""
    rows = ['a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    rows += [f"{b}: &{b} [{', '.join(['*' + a] * 9)}]" for a, b in zip("abc", "bcd", strict=True)]
    bomb = write_file(tmp_path, "\n".join(rows) + "\n", "bomb.yaml")
    with pytest.raises(ConfigError, match=r"bomb\.yaml line 1: YAML anchors \(&name\) are not allowed"):
        load(bomb)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("rcm: {Kp: &k 300.0, Kd: *k}\n", r"line 1: YAML anchors"),  # would load silently as Kd = 300
        ("rcm:\n  Kp: 300.0\n  Kd: *k\n", r"line 3: YAML aliases \(\*name\) are not allowed"),
        ("rcm: {<<: {Kp: 1.0}}\n", r"line 1: unknown config key 'rcm\.<<'"),  # no merge keys
        ("rcm: {Kp: !!binary aGVsbG8=}\n", r"line 1: YAML tag .*binary.* is not allowed"),
        ("rcm: !!python/object:os.system {}\n", r"line 1: YAML tag .*python.* is not allowed"),
        ("? [a, b]\n: 1\n", r"line 1: a config key must be a plain name"),
        ("rcm: {Kp: 2001-02-30}\n", r"line 1: config key 'rcm\.Kp' must be a number, got '2001-02-30'"),
        ("[" * 1000 + "]" * 1000, r"line 1: nested deeper than"),
        ("[" + "1, " * 20_000 + "1]", r"line 1: more than 10000 YAML nodes"),
        ("rcm: {Kp: \x00}\n", r"is not valid YAML: line 1: character #x0000"),
        ("rcm: [unclosed\n", r"is not valid YAML: line 2, column 1"),
    ],
)
def test_yaml_beyond_a_plain_mapping_is_refused_with_its_line(tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(ConfigError, match=r"c\.yaml " + match) as err:
        load(write_file(tmp_path, text))
    assert "\n" not in str(err.value)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("rcm:\n  Kp: 1.0\n  Kd: 2.0\n  Kp: 3.0\n", r"line 4: config key 'rcm\.Kp' appears twice \(first on line 2\)"),
        ("rcm: {Kp: 1.0}\nscope: {}\nrcm: {Kd: 2.0}\n", r"line 3: config key 'rcm' appears twice \(first on line 1\)"),
        ("rcm: {Kp: 1.0, Kp: 1}\n", r"line 1: config key 'rcm\.Kp' appears twice"),
    ],
)
def test_duplicate_keys_are_refused_with_their_path_and_line(tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        load(write_file(tmp_path, text))


def test_a_file_over_one_mebibyte_is_refused_without_reading_it_all(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    big = write_file(tmp_path, "# " + "x" * config_yaml.MAX_BYTES + "\nrcm: {Kp: 1.0}\n", "big.yaml")
    sizes: list[int] = []
    real_open = Path.open

    def spy_open(self: Path, *args: object, **kwargs: object) -> object:
        f = real_open(self, *args, **kwargs)
        real_read = f.read
        f.read = lambda n=-1: (sizes.append(n), real_read(n))[1]  # type: ignore[method-assign]
        return f

    monkeypatch.setattr(Path, "open", spy_open)
    with pytest.raises(ConfigError, match=r"big\.yaml is larger than 1024 KiB"):
        load(big)
    assert sizes == [config_yaml.MAX_BYTES + 1]
    monkeypatch.undo()
    assert load(write_file(tmp_path, "# " + "x" * 100_000 + "\nrcm: {Kp: 100.0}\n")).rcm.Kp == 100.0


def test_files_that_are_not_readable_text(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(ConfigError, match=r"latin1\.yaml is not UTF-8 text"):
        load(write_file(tmp_path, "rcm: {Kp: 1.0}  # café\n".encode("latin-1"), "latin1.yaml"))
    with pytest.raises(ConfigError, match="is a directory, not a file"):
        load(tmp_path)
    with pytest.raises(ConfigError, match="config file not found"):
        load(tmp_path / "missing.yaml")
    with pytest.raises(ConfigError, match="not found"):
        load("bad\x00name.yaml")
    locked = write_file(tmp_path, "rcm: {Kp: 1.0}\n", "locked.yaml")

    def refuse(self: Path, *args: object, **kwargs: object) -> None:
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "open", refuse)  # chmod does not stop root, which CI may be
    with pytest.raises(ConfigError, match=r"locked\.yaml cannot be read: Permission denied"):
        load(locked)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("rcm: {feedforward: !!bool maybe}\n", r"line 1: YAML value 'maybe' is not a valid !!bool"),  # was KeyError
        ("rcm:\n  feedforward: !!bool ''\n", r"line 2: YAML value '' is not a valid !!bool"),
        ("!!bool maybe: 1\n", r"line 1: YAML value 'maybe' is not a valid !!bool"),  # a key
        ("rcm: {Kp: !!int ''}\n", r"line 1: YAML value '' is not a valid !!int"),  # was IndexError
        ("rcm: {Kp: !!int '+'}\n", r"line 1: YAML value '\+' is not a valid !!int"),
        ("rcm: {Kp: !!float '_'}\n", r"line 1: YAML value '_' is not a valid !!float"),
        ("rcm:\n  Kd: 20.0\n  Kp: !!float abc\n", r"line 3: YAML value 'abc' is not a valid !!float"),
    ],
)
def test_a_value_its_explicit_tag_cannot_read_is_one_error_with_its_line(tmp_path: Path, text: str, match: str) -> None:
    """PyYAML's constructors raise KeyError / IndexError on these, which escaped as a traceback."""
    with pytest.raises(ConfigError, match=r"c\.yaml " + match) as err:
        load(write_file(tmp_path, text))
    assert "\n" not in str(err.value)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        # YAML 1.1 (PyYAML) reads these as 8, 512, 90 and 300.0: silently not what was written
        ("interaction: {k_min: 010}\n", r"line 1: '010' has a leading zero"),
        ("robot:\n  control_rate_hz: 01000\n", r"line 2: '01000' has a leading zero"),
        ("interaction: {k_min: 1:30}\n", r"line 1: '1:30' is a base-60 number"),
        ("rcm: {Kp: 5:00.0}\n", r"line 1: '5:00.0' is a base-60 number"),
        ("rcm: {Kp: !!int 0_10}\n", r"line 1: '0_10' has a leading zero"),
    ],
)
def test_numbers_yaml_1_1_reads_as_octal_or_base_60_are_refused(tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(ConfigError, match=r"c\.yaml " + match) as err:
        load(write_file(tmp_path, text))
    assert "\n" not in str(err.value)


def test_unambiguous_integer_forms_still_load(tmp_path: Path) -> None:
    cfg = load(write_file(tmp_path, "interaction: {k_min: 0x0A, contact_threshold: 0}\nscope: {grip_mass: -0}\n"))
    assert (cfg.interaction.k_min, cfg.interaction.contact_threshold, cfg.scope.grip_mass) == (10, 0, 0)
    assert load(write_file(tmp_path, "interaction: {k_min: 7, force_range: 0200.5}\n")).interaction.force_range == 200.5


def test_a_bad_list_element_is_named_with_its_own_line(tmp_path: Path) -> None:
    text = "scope:\n  grip_com:\n    - 0.0\n    - 0.0\n    - 5.0\n"
    with pytest.raises(ConfigError, match=r"c\.yaml line 5: config key 'scope\.grip_com\[2\]' must lie in"):
        load(write_file(tmp_path, text))
