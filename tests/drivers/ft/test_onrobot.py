"""The OnRobot HEX driver against the simulated compute box on loopback UDP: scaling, device commands, tare."""

from __future__ import annotations

import numpy as np
from helpers import wait_until

from lapwrench.drivers.ft import (
    CMD_BIAS,
    CMD_SET_FILTER,
    CMD_SET_SPEED,
    CMD_START_REALTIME,
    OnRobotHexSensor,
)
from lapwrench.drivers.simulated_hex import SimulatedHexBox


# --------------------------------------------------------------------------- HEX
def test_hex_scaling_defaults(device: SimulatedHexBox) -> None:
    device.counts = np.array([10000, -20000, 5000, 100000, -250000, 0])
    with OnRobotHexSensor(*device.address) as s:
        s0 = s.latest()
        assert s0 is not None
        w = s.buffer.wait_newer(s0.seq + 2, timeout=2.0).value
        np.testing.assert_allclose(w.force, [1.0, -2.0, 0.5])
        np.testing.assert_allclose(w.torque, [1.0, -2.5, 0.0])
        assert w.force.shape == (3,) and w.torque.shape == (3,)
        assert not w.force.flags.writeable
    assert (CMD_START_REALTIME, 0) in device.commands


def test_hex_configurable_scaling_and_device_commands(device: SimulatedHexBox) -> None:
    device.counts = np.array([500, 0, 0, 0, 0, 2000])
    with OnRobotHexSensor(
        *device.address, counts_per_force=100, counts_per_torque=1000, rate_hz=500, filter_code=4
    ) as s:
        w = s.buffer.wait_newer(s.latest().seq, timeout=2.0).value
        np.testing.assert_allclose(w.force, [5.0, 0, 0])
        np.testing.assert_allclose(w.torque, [0, 0, 2.0])
        s.set_hardware_bias(True)
        assert wait_until(lambda: (CMD_BIAS, 0xFF) in device.commands)
    # speed word = 1000 / rate_hz, filter code, then start (order as the public drivers)
    cmds = [c for c, _ in device.commands]
    assert cmds.index(CMD_SET_SPEED) < cmds.index(CMD_SET_FILTER) < cmds.index(CMD_START_REALTIME)
    assert (CMD_SET_SPEED, 2) in device.commands
    assert (CMD_SET_FILTER, 4) in device.commands


def test_hex_tare_removes_offset(device: SimulatedHexBox) -> None:
    offset = np.array([12000, -3000, 40000, 5000, 0, -7000])
    device.counts = offset
    with OnRobotHexSensor(*device.address) as s:
        bias = s.tare(n_samples=20, timeout=2.0)
        np.testing.assert_allclose(bias.force, offset[:3] / 1e4)  # counts in WIRE_ORDER: force first
        np.testing.assert_allclose(bias.torque, offset[3:] / 1e5)
        np.testing.assert_allclose(s.bias.torque, bias.torque)
        w = s.buffer.wait_newer(s.latest().seq, timeout=2.0).value
        np.testing.assert_allclose(w.force, 0.0, atol=1e-12)
        np.testing.assert_allclose(w.torque, 0.0, atol=1e-12)
        device.counts = offset + np.array([10000, 0, 0, 0, 0, 100000])  # surgeon pushes 1 N, 1 Nm
        assert wait_until(lambda: abs(s.latest().value.force[0] - 1.0) < 1e-9)
        np.testing.assert_allclose(s.latest().value.torque, [0, 0, 1.0], atol=1e-12)
        s.clear_bias()
        assert wait_until(lambda: abs(s.latest().value.force[0] - 2.2) < 1e-9)
