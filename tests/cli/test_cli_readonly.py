"""Commands that only look leave every register of the drive as they found it (a served twin, across processes)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from contextlib import AbstractContextManager
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
pytest.importorskip("serial")

from joints.clock import MonotonicClock
from joints.devices.erob.registers import EROB_MODBUS
from joints.devices.registers import RegisterTable
from joints.devices.zlac.registers import ZLAC8015D
from joints.drivers.access import ModbusAccess
from joints.link.modbus import ModbusLink
from joints.transports.serial import SerialTransport

ROOT = Path(__file__).resolve().parents[2]

DEVICES = {
    "erob": ("erob_stand.xml", 'device = "erob"\naddress = 2\nmjcf_joint = "joint1"\n', EROB_MODBUS, 2,
             ["actual_position", "error_code", "modbus_communication_timeout_duration"]),
    "zlac8015d": ("zlac_diffdrive.xml", 'device = "zlac8015d"\naddress = 1\nchannel = "left"\nmjcf_joint = "left_wheel"\n',
                  ZLAC8015D, 1,
                  ["actual_motor_position_left", "communication_offline_time"]),
}


def _image(port: str, table: RegisterTable, slave: int) -> dict[str, int]:
    """Every readable register of the drive (settings and status), read in blocks."""
    names = [r.name for r in table if r.access.readable]
    with SerialTransport(port, 115200) as t:
        access = ModbusAccess(ModbusLink(t, clock=MonotonicClock()), slave, table)
        out: dict[str, int] = {}
        for reg in (table[n] for n in names):  # one register at a time: no assumption about gaps
            out[reg.name] = access.read(reg.name)
        return out


#: status values that change by themselves (the drive runs: temperature model, voltages; a disabled ZLAC wheel's
#: measured speed flicks to 3 (0.3 r/min) and back with no command, at 0.86-0.89 s of a fresh world, so an
#: image read across that instant differs with no command sent)
LIVE = {"part_of_power_temperature", "bus_voltage", "motor_temperature", "dc_voltage", "software_connected_status",
        "hall_state", "actual_velocity_left", "actual_velocity_right"}


@pytest.mark.parametrize("device", sorted(DEVICES))
def test_read_only_commands_change_no_register(device: str, tmp_path: Path,
                                               sim_server: Callable[..., AbstractContextManager[str]]) -> None:
    model, joint, table, slave, registers = DEVICES[device]
    served = tmp_path / "served.toml"
    served.write_text(f'backend = "sim"\n[sim]\nmodel = "{model}"\n[buses.rs485]\nprotocol = "modbus-rtu"\n'
                      f'[joints.j]\nbus = "rs485"\n{joint}', encoding="utf-8")
    with sim_server(served) as port:
        hw = tmp_path / "hw.toml"
        hw.write_text(f'backend = "hardware"\n[buses.rs485]\nprotocol = "modbus-rtu"\nport = "{port}"\n'
                      f'[joints.j]\nbus = "rs485"\n{joint}', encoding="utf-8")
        before = _image(port, table, slave)
        for args in (["state", str(hw)], ["read", str(hw), "j", *registers],
                     ["monitor", str(hw), "--duration", "0.3", "--period", "0.05"]):
            proc = subprocess.run([sys.executable, "-m", "joints", *args], cwd=ROOT, capture_output=True, text=True,
                                  timeout=60, check=False)
            assert proc.returncode == 0, (args, proc.stderr)
        after = _image(port, table, slave)
    changed = {k: (before[k], after[k]) for k in before if before[k] != after[k] and k not in LIVE}
    assert not changed, f"read-only commands changed registers: {changed}"
    assert len(before) > 40  # the whole readable table was compared
