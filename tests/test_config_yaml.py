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
