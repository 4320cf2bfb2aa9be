"""Live parameters: validated as the YAML configuration is; the panel shows errors."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from lapwrench.config import Config
from lapwrench.ui.inputs import UiInputError
from lapwrench.ui.params import PARAMS, ParamsPanel, config_with

viser = pytest.importorskip("viser")


def test_good_values_make_a_new_config(cfg: Config) -> None:
    new = config_with(cfg, {"viscous.k_t": 80.0, "adaptive_rcm.enabled": False, "envelope.depth_max": 0.1})
    assert new.viscous.k_t == 80.0 and not new.adaptive_rcm.enabled and new.envelope.depth_max == 0.1
    assert cfg.viscous.k_t == 150.0  # the old one is unchanged


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"tracking.epsilon2": 10.0}, "epsilon2"),  # below epsilon1: the relation check
        ({"tracking.F_max": 500.0}, "F_max"),  # out of its range
        ({"viscous.k_t": float("nan")}, "finite"),
        ({"viscous.k_f": "fast"}, "not a number"),
        ({"adaptive_rcm.enabled": 1.0}, "on or off"),
        ({"robot.kind": "ur5"}, "unknown parameter"),
    ],
)
def test_bad_values_are_refused_with_the_configs_message(cfg: Config, values: dict, message: str) -> None:
    with pytest.raises(UiInputError, match=message):
        config_with(cfg, values)


class FakeSession:
    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        self.requested: list[Config] = []
        self.config_pending = False

    def request_config(self, cfg: Config) -> None:
        self.requested.append(cfg)
        self.config_pending = True


@pytest.fixture
def server() -> Iterator[object]:
    s = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield s
    s.stop()


def test_the_panel_shows_an_error_or_hands_a_good_set_to_the_session(cfg: Config, server: object) -> None:
    session = FakeSession(cfg)
    panel = ParamsPanel(server.gui, session)  # type: ignore[attr-defined]
    assert set(panel.inputs) == {p.path for p in PARAMS}
    panel.inputs["tracking.epsilon2"].value = 20.0
    assert not panel.apply()
    assert "Parameter error" in panel.status.content and "epsilon2" in panel.status.content
    assert session.requested == []
    panel.inputs["tracking.epsilon2"].value = 250.0
    assert panel.apply()
    assert session.requested[-1].tracking.epsilon2 == 250.0
    session.config_pending = False
    panel.show_applied()
    assert panel.status.content == "Parameters applied."
