"""UdpForceTorqueSensor: tare, polled mode (no thread) and constructor checks."""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest

from lapwrench.drivers.base import DeviceTimeoutError
from lapwrench.drivers.ft import (
    AtiNetFTSensor,
    OnRobotHexSensor,
)
from lapwrench.drivers.simulated_hex import SimulatedHexBox


def test_tare_averages_noisy_samples(device: SimulatedHexBox) -> None:
    # alternate +-1000 counts around 5000: mean of an even number of samples is exact
    device.counts_fn = lambda i: [5000 + (1000 if i % 2 else -1000), 0, 0, 0, 0, 0]
    with OnRobotHexSensor(*device.address) as s:
        bias = s.tare(n_samples=40, timeout=2.0)
        assert bias.force[0] == pytest.approx(0.5, abs=0.1 / 40 + 1e-9)


def test_tare_requires_running_source(device: SimulatedHexBox) -> None:
    s = OnRobotHexSensor(*device.address)
    with pytest.raises(RuntimeError, match="running"):
        s.tare()


def test_constructor_validation() -> None:
    with pytest.raises(ValueError):
        AtiNetFTSensor("127.0.0.1", 1, counts_per_force=0)
    with pytest.raises(ValueError):
        OnRobotHexSensor("127.0.0.1", 1, filter_code=9)
    with pytest.raises(ValueError):
        OnRobotHexSensor("127.0.0.1", 1, rate_hz=5000)
    s = OnRobotHexSensor("127.0.0.1", 1)
    with pytest.raises(ValueError):
        s.set_bias(force=[np.nan, 0, 0], torque=np.zeros(3))
    s.set_bias(force=[1.0, 2.0, 3.0], torque=[0.1, 0.2, 0.3])
    np.testing.assert_array_equal(s.bias.force, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(s.bias.torque, [0.1, 0.2, 0.3])


def test_polled_tare_drains_by_itself(device: SimulatedHexBox) -> None:
    device.counts = np.array([12000, -3000, 40000, 5000, 0, -7000])
    s = OnRobotHexSensor(*device.address).start_polled()
    try:
        bias = s.tare(n_samples=20, timeout=2.0)
        np.testing.assert_allclose(bias.force, device.counts[:3] / 1e4)
        np.testing.assert_allclose(bias.torque, device.counts[3:] / 1e5)
        time.sleep(0.02)
        s.drain()
        np.testing.assert_allclose(s.latest().value.force, 0.0, atol=1e-12)
        np.testing.assert_allclose(s.latest().value.torque, 0.0, atol=1e-12)
    finally:
        s.stop()


def test_polled_start_without_device_times_out_clearly() -> None:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]  # bound but silent
    try:
        s = OnRobotHexSensor("127.0.0.1", port, start_timeout=0.3)
        with pytest.raises(DeviceTimeoutError, match=f"udp://127.0.0.1:{port}"):
            s.start_polled()
        assert not s.polled and s.drain() == 0  # stopped: draining a closed source is a no-op
    finally:
        sock.close()
