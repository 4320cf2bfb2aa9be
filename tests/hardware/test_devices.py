"""The devices of ``lapwrench run``: the tactile wire format from the command line or the config, and
the dry run's simulated tactile array."""

from __future__ import annotations

import argparse
import os

import numpy as np
import pytest

from lapwrench import config as config_mod
from lapwrench.drivers.tactile import ChecksumType, SerialTactileArray, TactileFrameFormat
from lapwrench.hardware import cli as hw
from lapwrench.hardware.devices import CliError, Devices, DryRunScript, TactileWriter, open_sources, tactile_format


def parse(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    hw.add_run_arguments(p)
    return p.parse_args(argv)


# -- the tactile wire format from the command line and the config ----------------------------------------------
def test_tactile_format_comes_from_the_config_and_the_options_override_it() -> None:
    cfg = config_mod.load()
    assert tactile_format(parse([]), cfg) == TactileFrameFormat()  # the packaged config: the driver default
    custom = cfg.replace(tactile={"header": "A5", "checksum": "sum8", "length_byte": True})
    fmt = tactile_format(parse([]), custom)
    assert (fmt.header, fmt.checksum, fmt.length_byte) == (b"\xa5", ChecksumType.SUM8, True)
    fmt = tactile_format(parse(["--tactile-checksum", "crc16-modbus", "--tactile-header", "55AA"]), custom)
    assert (fmt.header, fmt.checksum, fmt.length_byte) == (b"\x55\xaa", ChecksumType.CRC16_MODBUS, True)
    older = argparse.Namespace()  # a configuration object without the tactile section
    assert tactile_format(parse([]), older) == TactileFrameFormat()


def test_the_dry_run_tactile_array_speaks_the_chosen_format() -> None:
    """The simulated array writes, and the real reader reads, the format of the options (in-process path)."""
    cfg = config_mod.load()
    args = parse(["--dry-run", "--no-tare", "--tactile-checksum", "crc16-modbus", "--tactile-header", "C3"])
    args.tactile_frame_format = tactile_format(args, cfg)
    devices = Devices()
    try:
        sources, described = open_sources(args, cfg, devices, DryRunScript())
        assert sources.tactile is not None and "tactile" in described
    finally:
        devices.close()


def test_a_reader_of_another_format_gets_no_frame() -> None:
    """What the dry run would hit if the writer ignored the chosen format: no valid frame."""
    master, slave = os.openpty()
    writer = TactileWriter(master, lambda: np.full(64, 7, np.uint8), fmt=TactileFrameFormat()).start()
    reader = SerialTactileArray(os.ttyname(slave), 115200, TactileFrameFormat(checksum="crc16-modbus"))
    try:
        reader.start()
        assert reader.buffer.wait_newer(0, timeout=0.5) is None
    finally:
        reader.stop()
        writer.stop()
        os.close(master)
        os.close(slave)


def test_a_tactile_config_the_driver_refuses_is_a_cli_error() -> None:
    class Section:
        header, checksum, length_byte, checksum_includes_header = "zz", "none", False, False

    cfg = argparse.Namespace(tactile=Section())
    with pytest.raises(CliError, match=r"tactile\.header"):
        tactile_format(parse([]), cfg)


def test_a_registered_input_driver_that_fails_to_start_is_one_line_naming_it(monkeypatch: pytest.MonkeyPatch) -> None:
    import dataclasses

    from fake_plugins import FAKE, PEDAL, install

    from lapwrench import plugins
    from lapwrench.config import from_dict
    from lapwrench.hardware.devices import CliError, Devices, open_registered_inputs

    def broken(cfg: object) -> object:
        raise OSError("no such device /dev/pedal")

    install(monkeypatch)
    monkeypatch.setitem(FAKE[plugins.INPUT_GROUP], "pedal", dataclasses.replace(PEDAL, open=broken))
    devices = Devices()
    with pytest.raises(CliError, match=r"input 'pedal': its driver failed to start: OSError: no such device"):
        open_registered_inputs(from_dict({"cues": {"pedal_hold": {}}}), devices, {})
    devices.close()
