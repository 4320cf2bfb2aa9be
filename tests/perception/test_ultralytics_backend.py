"""ultralytics backend: lazy import with a clear error when the extra is absent."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from lapwrench.perception import BackendUnavailableError, ModelError, UltralyticsDetector, make_detector


def test_missing_ultralytics_gives_install_hint(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setitem(sys.modules, "ultralytics", None)  # import ultralytics -> ImportError
    weights = tmp_path / "best.pt"
    weights.write_bytes(b"not really weights")
    with pytest.raises(BackendUnavailableError, match=r"train.*extra|extra.*train"):
        UltralyticsDetector(weights)
    with pytest.raises(ImportError):  # also an ImportError for generic handlers
        make_detector(weights)


def test_importing_perception_does_not_import_ultralytics() -> None:
    # The package import must stay light: no torch/ultralytics pulled in by lapwrench.perception.
    import lapwrench.perception  # noqa: F401

    assert "lapwrench.perception.ultralytics_backend" in sys.modules
    if "ultralytics" not in sys.modules:
        assert "torch" not in sys.modules


def test_real_backend_missing_weights(tmp_path: Path) -> None:
    pytest.importorskip("ultralytics")
    with pytest.raises(ModelError, match="not found"):
        UltralyticsDetector(tmp_path / "missing.pt")


def test_real_backend_corrupt_weights(tmp_path: Path) -> None:
    pytest.importorskip("ultralytics")
    weights = tmp_path / "corrupt.pt"
    weights.write_bytes(np.random.default_rng(0).integers(0, 256, 256, dtype=np.uint8).tobytes())
    with pytest.raises(ModelError):
        UltralyticsDetector(weights)
