"""The long run log the reader and log-report tests cut and damage."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from hardware.log.support import N_LONG, write

from lapwrench.hardware.log import read_log


@pytest.fixture(scope="module")
def long_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[dict[str, Any]]]:
    """A complete log of ``N_LONG`` cycles, and its cycles read back."""
    path = tmp_path_factory.mktemp("long") / "run.mcap"
    write(path, N_LONG)
    return path, read_log(path)[0]
