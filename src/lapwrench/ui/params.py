"""Live parameters on the page: damping, the tracking deadbands ε1/ε2, F_max, RCM adaptation on/off
and the envelope limits (issue 9).

The page's values are validated exactly as the YAML configuration is: each number must be finite,
then :meth:`Config.replace` checks its range and the relations between keys (ε2 > ε1, depth_min <
depth_max, ...). A bad value raises :class:`~lapwrench.ui.inputs.UiInputError` with the config's own
message, shown on the page; the simulation keeps running with the parameters it had. A good set is
handed to :meth:`Session.request_config` (a new controller, swapped in when the arm is at rest).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from lapwrench.config import Config
from lapwrench.config_ranges import ConfigError
from lapwrench.ui.inputs import UiInputError, checked_number
from lapwrench.ui.session import Session


@dataclass(frozen=True)
class Param:
    """One live parameter: ``section.key`` of the configuration, its label and slider step."""

    section: str
    key: str
    label: str
    step: float = 0.1
    boolean: bool = False

    @property
    def path(self) -> str:
        return f"{self.section}.{self.key}"

    def value(self, cfg: Config) -> Any:
        return getattr(getattr(cfg, self.section), self.key)


PARAMS: tuple[Param, ...] = (
    Param("viscous", "k_t", "damping k_t (N m s)", 1.0),
    Param("viscous", "k_f", "damping k_f (N s/m)", 1.0),
    Param("tracking", "epsilon1", "ε1 (px)", 1.0),
    Param("tracking", "epsilon2", "ε2 (px)", 1.0),
    Param("tracking", "F_max", "F_max (N)", 0.5),
    Param("adaptive_rcm", "enabled", "RCM adaptation", boolean=True),
    Param("envelope", "pivot_speed_max", "pivot speed max (rad/s)", 0.01),
    Param("envelope", "insertion_speed_max", "insertion speed max (m/s)", 0.005),
    Param("envelope", "depth_min", "depth min (m)", 0.005),
    Param("envelope", "depth_max", "depth max (m)", 0.005),
    Param("envelope", "roll_range", "roll range (rad)", 0.05),
)


def config_with(cfg: Config, values: dict[str, object]) -> Config:
    """``cfg`` with the page's ``values`` (``section.key`` -> value), validated as the YAML is.

    Raises:
        UiInputError: a value is not a finite number (or not a bool for a switch), an unknown key,
            or the configuration refuses it (its message: range, relation between keys).
    """
    known = {p.path: p for p in PARAMS}
    sections: dict[str, dict[str, object]] = {}
    for path, raw in values.items():
        p = known.get(path)
        if p is None:
            raise UiInputError(f"unknown parameter {path[:60]!r}")
        if p.boolean:
            if not isinstance(raw, bool):
                raise UiInputError(f"{p.label}: must be on or off, got {str(raw)[:40]!r}")
            v: object = raw
        else:
            v = checked_number(raw, p.label, -1e300, 1e300)
        sections.setdefault(p.section, {})[p.key] = v
    try:
        return cfg.replace(**sections)
    except ConfigError as exc:
        raise UiInputError(str(exc)) from exc


class ParamsPanel:
    """The parameter inputs, an Apply button and a status line, in a folder of the page."""

    def __init__(self, gui: Any, session: Session) -> None:
        self.session = session
        self.inputs: dict[str, Any] = {}
        with gui.add_folder("Live parameters", expand_by_default=False):
            for p in PARAMS:
                v = p.value(session.cfg)
                if p.boolean:
                    self.inputs[p.path] = gui.add_checkbox(p.label, bool(v))
                else:
                    self.inputs[p.path] = gui.add_number(p.label, float(v), step=p.step)
            self.apply_button = gui.add_button("Apply parameters")
            self.status = gui.add_markdown("Parameters: as loaded.")
        self.apply_button.on_click(lambda _event: self.apply())

    def apply(self) -> bool:
        """Validate the inputs and hand a good set to the session; the status says what happened."""
        try:
            cfg = config_with(self.session.cfg, {path: h.value for path, h in self.inputs.items()})
            self.session.request_config(cfg)
        except UiInputError as exc:
            self.status.content = f"**Parameter error:** {exc}"
            return False
        self.status.content = "Parameters accepted: applied as soon as the arm is at rest."
        return True

    def show_applied(self) -> None:
        """Called by the page loop: say when a pending set has been applied."""
        if not self.session.config_pending and self.status.content.startswith("Parameters accepted"):
            self.status.content = "Parameters applied."
