"""Configuration loading and validation."""

from __future__ import annotations

import ast
import typing
from pathlib import Path

import pytest
import yaml
from helpers import write_file

from lapwrench import config, config_ranges, config_yaml
from lapwrench.config import Config, ConfigError, TactileConfig, dump, from_dict, load
from lapwrench.drivers.tactile import ChecksumType, TactileFrameFormat


def test_defaults_are_the_paper_parameters() -> None:
    cfg = load()
    assert cfg == Config()
    assert (cfg.interaction.k_H, cfg.interaction.k_min) == (2000.0, 3)
    assert (cfg.camera.u0, cfg.camera.v0, cfg.camera.fx, cfg.camera.fy) == (312.22, 243.39, 506.57, 506.72)
    assert (cfg.tracking.epsilon1, cfg.tracking.epsilon2, cfg.tracking.F_max) == (50.0, 200.0, 10.0)
    assert (cfg.rcm.Kp, cfg.rcm.Kd) == (300.0, 20.0)
    assert (cfg.scope.length, cfg.scope.lambda0) == (0.29, 0.8)
    a = cfg.adaptive_rcm
    assert (a.F_op, a.gamma1, a.gamma2, a.alpha, a.beta, a.epsilon) == (10.0, 5.0, 15.0, 0.003, 0.05, 5e-4)
    # k_t as printed for the hand; k_f and the unguided k_t depart from the table (README, "damping")
    assert (cfg.viscous.k_t, cfg.viscous.k_f, cfg.viscous.k_t_unguided) == (150.0, 150.0, 2.0)


def test_round_trip(tmp_path: Path) -> None:
    cfg = load().replace(tracking={"ramp": "c1"}, robot={"kind": "fr3"})
    dump(cfg, tmp_path / "c.yaml")
    assert load(tmp_path / "c.yaml") == cfg


@pytest.mark.parametrize(
    ("data", "key"),
    [
        ({"tracking": {"epsilon3": 1.0}}, "tracking.epsilon3"),
        ({"trackin": {}}, "trackin"),
        ({"rcm": {"Kp": "high"}}, "rcm.Kp"),
        ({"interaction": {"k_min": 2.5}}, "interaction.k_min"),
        ({"adaptive_rcm": {"enabled": "yes"}}, "adaptive_rcm.enabled"),
        ({"rcm": {"Kd": 0.0}}, "rcm.Kd"),
        ({"rcm": {"Kp": -300.0}}, "rcm.Kp"),
        ({"tracking": {"epsilon1": 0}}, "tracking.epsilon1"),
        ({"adaptive_rcm": {"gamma1": -1.0}}, "adaptive_rcm.gamma1"),
        ({"viscous": {"k_t": float("nan")}}, "viscous.k_t"),
        ({"tracking": {"epsilon1": 200.0, "epsilon2": 200.0}}, "tracking.epsilon2"),
        ({"tracking": {"epsilon1": 250.0}}, "tracking.epsilon2"),
        ({"adaptive_rcm": {"gamma2": 4.0}}, "adaptive_rcm.gamma2"),
        ({"tracking": {"ramp": "cubic"}}, "tracking.ramp"),
        ({"robot": {"kind": "ur5e"}}, "robot.kind"),
        ({"robot": {"kind": "kuka"}}, "robot.kind"),
        ({"scope": {"lambda0": 1.5}}, "scope.lambda0"),
        ({"rcm": [1, 2]}, "rcm"),
    ],
)
def test_bad_values_name_the_key(data: dict, key: str) -> None:
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        from_dict(data)


def test_bad_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not found"):
        load(tmp_path / "missing.yaml")
    with pytest.raises(ConfigError, match="config file name is empty"):  # not "config file  is a directory"
        load("")
    bad = tmp_path / "bad.yaml"
    bad.write_text("rcm: [unclosed\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load(bad)
    typo = tmp_path / "typo.yaml"
    typo.write_text(yaml.safe_dump({"viscous": {"kt": 1.0}}))
    with pytest.raises(ConfigError, match=r"typo\.yaml.*viscous\.kt"):
        load(typo)


# --- issue 11, item 11: the loader refuses what could explode, and ranges match physical sense ---------------------


def test_huge_numbers_in_a_file_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"line 1: config key 'rcm\.Kp' is too large"):
        load(write_file(tmp_path, "rcm: {Kp: " + "9" * 90 + "0" * 310 + "}\n"))  # 400 digits: OverflowError before
    with pytest.raises(ConfigError, match=r"line 1: number longer than 1000 characters"):
        load(write_file(tmp_path, "rcm: {Kp: " + "9" * 10_000 + "}\n"))  # int() would refuse beyond 4300 digits
    with pytest.raises(ConfigError, match=r"line 2: config key 'rcm\.Kd' must be finite"):
        load(write_file(tmp_path, "rcm:\n  Kd: 1e400\n"))


def test_exponents_without_a_dot_are_numbers(tmp_path: Path) -> None:
    """YAML 1.1 reads 3e-3 as text; in a config it is the number a user means (as in YAML 1.2)."""
    cfg = load(write_file(tmp_path, "adaptive_rcm: {alpha: 3e-3, epsilon: 5E-4}\nrcm: {Kp: 1e3}\n"))
    assert (cfg.adaptive_rcm.alpha, cfg.adaptive_rcm.epsilon, cfg.rcm.Kp) == (0.003, 5e-4, 1000.0)


def test_the_values_the_code_and_tests_use_still_load() -> None:
    """Bounds stay generous: every preset, and the unusual values the suite and the demo use on purpose."""
    for name in config.presets():
        load(name)
    cfg = load()
    for rate in (250, 500, 2000):  # `run` and `demo` refuse these themselves, with their own message
        cfg.replace(robot={"control_rate_hz": rate})
    cfg.replace(safety={"max_rcm_error": 1e-5}, viscous={"k_t": 0.5, "k_f": 2.0, "k_t_unguided": 150.0})
    cfg.replace(scope={"oblique_angle_deg": 30.0}, motion={"joint_limit_stiffness": 0.0})
    cfg.replace(camera={"width": 1920, "height": 1080, "u0": 960.5, "v0": 540.5, "fx": 1400.0, "fy": 1400.0})


def test_error_messages_quote_only_a_short_prefix(tmp_path: Path) -> None:
    long = "x" * 1_000_000
    for data in ({"robot": {"kind": long}}, {"rcm": {"Kp": long}}, {long: 1}, {"rcm": {long: 1}},
                 {"rcm": {"Kp": list(range(100_000))}}, {"tactile": {"header": long}}):
        with pytest.raises(ConfigError) as err:
            from_dict(data)
        assert len(str(err.value)) < 300 and "x" * 61 not in str(err.value)
    path = write_file(tmp_path, "robot: {kind: " + "y" * 900_000 + "}\n")
    with pytest.raises(ConfigError, match=r"line 1: config key 'robot\.kind'") as err:
        load(path)
    assert len(str(err.value)) < 300


def test_a_bad_value_in_a_file_names_its_line(tmp_path: Path) -> None:
    path = write_file(tmp_path, "# intrinsics\ncamera:\n  width: 640\n  u0: 900\n")
    with pytest.raises(ConfigError, match=r"c\.yaml line 4: config key 'camera\.u0' \(900\.0\) must lie inside"):
        load(path)


def test_tactile_wire_format_section(tmp_path: Path) -> None:
    assert load().tactile == TactileConfig(header="AA55", checksum="none", length_byte=False,
                                           checksum_includes_header=False)
    path = write_file(tmp_path, "tactile: {header: 'aa 55 01', checksum: crc16-modbus, length_byte: true}\n")
    t = load(path).tactile
    fmt = TactileFrameFormat(header=bytes.fromhex(t.header), checksum=t.checksum, length_byte=t.length_byte,
                             checksum_includes_header=t.checksum_includes_header)
    assert fmt.header == b"\xaa\x55\x01" and fmt.checksum_size == 2
    for header in ("", "zz", "AA5", "00" * 9, "0x55"):
        with pytest.raises(ConfigError, match=r"'tactile\.header' must be 1 to 8 bytes"):
            from_dict({"tactile": {"header": header}})
    with pytest.raises(ConfigError, match=r"'tactile\.header' must be text"):
        from_dict({"tactile": {"header": 1234}})
    with pytest.raises(ConfigError, match=r"'tactile\.checksum' must be one of"):
        from_dict({"tactile": {"checksum": "crc32"}})
    assert set(typing.get_args(config.TactileChecksum)) == {c.value for c in ChecksumType}


def test_config_does_not_depend_on_the_drivers() -> None:
    """Layering: the drivers read the config, never the other way round."""
    for module in (config, config_yaml, config_ranges):
        tree = ast.parse(Path(module.__file__).read_text())
        imported = [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
        imported += [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
        allowed = ("lapwrench.config_yaml", "lapwrench.config_ranges", "lapwrench.config_cues", "lapwrench.robot_kinds")
        assert not [m for m in imported if m.startswith("lapwrench.") and m not in allowed]


def test_to_dict_is_plain_yaml_data_that_reads_back() -> None:
    """Vectors (scope.grip_com, a cue's centre) are lists, so the dict survives a YAML or JSON round trip
    unchanged (a study stores it and compares it, and hashes it to resume), and builds the same Config."""
    import json

    from lapwrench.config import to_dict

    cfg = Config().replace(scope={"grip_com": [0.01, 0.0, 0.02]}, cues={"keep_out": {}})
    d = to_dict(cfg)
    assert d["scope"]["grip_com"] == [0.01, 0.0, 0.02]
    assert yaml.safe_load(yaml.safe_dump(d)) == d
    assert json.loads(json.dumps(d)) == d
    assert from_dict(d) == cfg


@pytest.mark.parametrize("header", ["AA55\n", "AA55\r\n", "\nAA55"])
def test_a_tactile_header_with_a_line_break_is_refused(header: str) -> None:
    """``$`` also matched before a final newline: "AA55\\n" was taken (and written back by dump)."""
    with pytest.raises(ConfigError, match=r"'tactile\.header' must be 1 to 8 bytes"):
        from_dict({"tactile": {"header": header}})


@pytest.mark.parametrize("name", ["a\nb.yaml", "a\rb.yaml", "a\x1b[2Jb.yaml"])
def test_a_config_file_name_with_control_characters_stays_one_line(tmp_path: Path, name: str) -> None:
    """The name is quoted in every message: a line break (or a terminal escape) in it must not split it."""
    with pytest.raises(ConfigError, match="config file not found") as err:
        load(tmp_path / name)
    assert "\n" not in str(err.value) and "\r" not in str(err.value) and "\x1b" not in str(err.value)
    with pytest.raises(ConfigError, match=r"line 1: unknown config key 'nope'") as err:
        load(write_file(tmp_path, "nope: 1\n", name))
    assert "\n" not in str(err.value) and "\r" not in str(err.value) and "\x1b" not in str(err.value)
