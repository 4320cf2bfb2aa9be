"""Configuration loading and validation."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from lapwrench.config import Config, ConfigError, dump, from_dict, load


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
        ({"robot": {"kind": "ur5"}}, "robot.kind"),
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
    bad = tmp_path / "bad.yaml"
    bad.write_text("rcm: [unclosed\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load(bad)
    typo = tmp_path / "typo.yaml"
    typo.write_text(yaml.safe_dump({"viscous": {"kt": 1.0}}))
    with pytest.raises(ConfigError, match=r"typo\.yaml.*viscous\.kt"):
        load(typo)
