"""lapwrench.wrenches.viscous: eq (40), with k_t while the handle is gripped and k_t_unguided otherwise."""

from __future__ import annotations

import numpy as np

from lapwrench.config import load
from lapwrench.sensors import TactileReading, ValidInputs
from lapwrench.wrenches.viscous import ViscousCue


class _Ctx:
    def __init__(self, tactile: TactileReading | None, J_G: np.ndarray, dq: np.ndarray) -> None:
        self.inputs = ValidInputs(tactile=tactile)
        self.geometry = type("G", (), {"J_G": J_G, "p_G": np.array([0.4, 0.0, 0.2])})()
        self.kin = type("K", (), {"dq": dq})()


def test_the_damping_follows_the_grip() -> None:
    cfg = load()
    cue = ViscousCue("viscous", cfg.viscous, cfg)
    v = cfg.viscous
    gripped = _Ctx(TactileReading(np.full(64, 100.0)), np.eye(6, 7), np.zeros(7))
    loose = _Ctx(None, np.eye(6, 7), np.zeros(7))
    np.testing.assert_allclose(np.diag(cue.damping_matrix(gripped)), [v.k_t] * 3 + [v.k_f] * 3)  # type: ignore[arg-type]
    np.testing.assert_allclose(np.diag(cue.damping_matrix(loose)), [v.k_t_unguided] * 3 + [v.k_f] * 3)  # type: ignore[arg-type]


def test_eq_40_opposes_the_closest_point_twist() -> None:
    cfg = load()
    cue = ViscousCue("viscous", cfg.viscous, cfg)
    rng = np.random.default_rng(1)
    J_G, dq = rng.normal(size=(6, 7)), rng.normal(size=7)
    ctx = _Ctx(None, J_G, dq)
    w = cue.compute(ctx)  # type: ignore[arg-type]
    np.testing.assert_allclose(w.vector, -cue.damping_matrix(ctx) @ J_G @ dq)  # type: ignore[arg-type]
    assert w.vector @ (J_G @ dq) < 0.0  # it dissipates
