"""ATI Net F/T real-time RDT streaming (NETBA/NETCANOEM, also Axia80).

Scaling assumption (configurable, check it against your device): 1000000 counts/N and 1000000
counts/Nm, the Net F/T default calibration with force in N and torque in N·m. The true values are
the device's "Counts per Force/Torque" settings (``cfgcpf``/``cfgcpt`` in
``http://<box>/netftapi2.xml``); torque in N·mm gives 1e9 counts/Nm (the value
``ati_netft_ros_driver`` hard-codes).
"""

from __future__ import annotations

from typing import Any

from lapwrench.drivers.ft.sensor import UdpForceTorqueSensor
from lapwrench.drivers.ft.wire import CMD_BIAS, DEFAULT_PORT

__all__ = ["AtiNetFTSensor"]


class AtiNetFTSensor(UdpForceTorqueSensor):
    """ATI Net F/T (NETBA/NETCANOEM, also Axia80 RDT) real-time RDT streaming.

    Args:
        host: Net F/T box address (ATI default 192.168.1.1).
        port: UDP port (49152 on the device).
        counts_per_force: Default 1000000 counts/N (Net F/T default calibration, force in N).
        counts_per_torque: Default 1000000 counts/Nm (torque in N·m). Read ``cfgcpf``/``cfgcpt``
            from ``netftapi2.xml`` on the box for the real values.
        **kwargs: Forwarded to :class:`UdpForceTorqueSensor`.
    """

    kind = "ATI Net F/T"

    def __init__(
        self,
        host: str,
        port: int = DEFAULT_PORT,
        *,
        counts_per_force: float = 1_000_000.0,
        counts_per_torque: float = 1_000_000.0,
        **kwargs: Any,
    ) -> None:
        super().__init__(
            host,
            port,
            counts_per_force=counts_per_force,
            counts_per_torque=counts_per_torque,
            **kwargs,
        )

    def set_hardware_bias(self) -> None:
        """Ask the Net F/T to bias itself (RDT command 0x0042, 'set software bias')."""
        self.send_command(CMD_BIAS, 0)
