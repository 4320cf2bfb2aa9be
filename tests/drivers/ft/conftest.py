"""The simulated OnRobot compute box every F/T driver test talks to over loopback UDP."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from helpers import FT_RATE_HZ

from lapwrench.drivers.simulated_hex import SimulatedHexBox


@pytest.fixture
def device() -> Iterator[SimulatedHexBox]:
    dev = SimulatedHexBox(rate_hz=FT_RATE_HZ).start()
    try:
        yield dev
    finally:
        dev.close()
