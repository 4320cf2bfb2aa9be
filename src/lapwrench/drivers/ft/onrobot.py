"""OnRobot HEX-E/HEX-H through its compute box (EtherDAQ UDP mode).

Scaling assumption (configurable, check it against your device): 10000 counts/N and 100000
counts/Nm, the defaults of the OnRobot/OptoForce EtherDAQ drivers (see
:mod:`~lapwrench.drivers.ft.wire`). The sensor's own calibration sheet is authoritative.
"""

from __future__ import annotations

from typing import Any

from lapwrench.drivers.ft.sensor import UdpForceTorqueSensor
from lapwrench.drivers.ft.wire import CMD_BIAS, CMD_SET_FILTER, CMD_SET_SPEED, DEFAULT_PORT

__all__ = ["OnRobotHexSensor"]


class OnRobotHexSensor(UdpForceTorqueSensor):
    """OnRobot HEX-E/HEX-H (as in the paper's handle) through its compute box, EtherDAQ UDP mode.

    Args:
        host: Compute box address (OnRobot default 192.168.1.1).
        port: UDP port (49152 on the device).
        counts_per_force: Default 10000 counts/N (OnRobot/OptoForce EtherDAQ driver default).
        counts_per_torque: Default 100000 counts/Nm (same source).
        rate_hz: If given, send the speed command (word = round(1000 / rate_hz)) before starting.
        filter_code: If given, send the filter command: 0 none, 1 500 Hz, 2 150 Hz, 3 50 Hz,
            4 15 Hz, 5 5 Hz, 6 1.5 Hz.
        hardware_bias: If not None, send the device bias command before starting (True: 0xFF
            bias on, False: 0x00 bias off). The software :meth:`tare` works either way.
        **kwargs: Forwarded to :class:`UdpForceTorqueSensor`.
    """

    kind = "OnRobot HEX"

    def __init__(
        self,
        host: str,
        port: int = DEFAULT_PORT,
        *,
        counts_per_force: float = 10000.0,
        counts_per_torque: float = 100000.0,
        rate_hz: float | None = None,
        filter_code: int | None = None,
        hardware_bias: bool | None = None,
        **kwargs: Any,
    ) -> None:
        if rate_hz is not None and not 1.0 <= rate_hz <= 1000.0:
            raise ValueError("rate_hz must be within [1, 1000]")
        if filter_code is not None and filter_code not in range(7):
            raise ValueError("filter_code must be 0..6")
        kwargs.setdefault("expected_rate_hz", rate_hz)
        super().__init__(
            host,
            port,
            counts_per_force=counts_per_force,
            counts_per_torque=counts_per_torque,
            **kwargs,
        )
        self.rate_hz = rate_hz
        self.filter_code = filter_code
        self.hardware_bias = hardware_bias

    def _configure_device(self) -> None:
        if self.rate_hz is not None:
            self.send_command(CMD_SET_SPEED, round(1000.0 / self.rate_hz))
        if self.filter_code is not None:
            self.send_command(CMD_SET_FILTER, self.filter_code)
        if self.hardware_bias is not None:
            self.set_hardware_bias(self.hardware_bias)

    def set_hardware_bias(self, enable: bool = True) -> None:
        """Toggle the compute box's own bias (command 0x0042, data 0xFF on / 0x00 off)."""
        self.send_command(CMD_BIAS, 0xFF if enable else 0x00)
