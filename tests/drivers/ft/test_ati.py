"""The ATI Net F/T RDT driver against the simulated box on loopback UDP: scaling, RDT commands, tare."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import wait_until

from lapwrench.drivers.ft import (
    CMD_BIAS,
    CMD_START_REALTIME,
    AtiNetFTSensor,
)
from lapwrench.drivers.simulated_hex import SimulatedHexBox


# --------------------------------------------------------------------------- ATI Net F/T
def test_netft_default_scaling_and_rdt_commands(device: SimulatedHexBox) -> None:
    device.counts = np.array([1_000_000, 2_500_000, -500_000, 1_000_000, 0, -3_000_000])
    with AtiNetFTSensor(*device.address) as s:
        w = s.buffer.wait_newer(s.latest().seq, timeout=2.0).value
        np.testing.assert_allclose(w.force, [1.0, 2.5, -0.5])
        np.testing.assert_allclose(w.torque, [1.0, 0.0, -3.0])
        s.set_hardware_bias()
        assert wait_until(lambda: (CMD_BIAS, 0) in device.commands)
    assert device.commands[0] == (CMD_START_REALTIME, 0)
    assert device.bad_requests == 0


def test_netft_custom_counts_tare_and_malformed(device: SimulatedHexBox) -> None:
    device.counts = np.array([3000, 0, 0, 0, 0, 0])
    with AtiNetFTSensor(*device.address, counts_per_force=1000, counts_per_torque=1e6) as s:
        assert s.buffer.wait_newer(s.latest().seq, timeout=2.0).value.force[0] == pytest.approx(3.0)
        s.tare(10)
        device.inject([b"\x12\x34" + b"\x00" * 6, b"\xff" * 36 + b"x"])
        device.counts = np.array([4000, 0, 0, 0, 0, 0])
        assert wait_until(lambda: abs(s.latest().value.force[0] - 1.0) < 1e-9)
        assert wait_until(lambda: s.status().malformed == 2)
        assert s.running
