"""ZLAC8015D procedures of the manual (chapter 3) reproduced by the driver, frame by frame.

Each manual sequence (corrected frames, vectors.json) is compared with the frames our driver
sends for the same high-level calls, against a scripted slave on the loopback transport.
"""

from __future__ import annotations

import json
from collections.abc import Callable

import pytest

from joints.clock import ManualClock
from joints.devices.zlac.profile import HubMotorProfile
from joints.devices.zlac.registers import ZLAC8015D, ControlMode
from joints.drivers.zlac_modbus import ZlacChannelDriver, ZlacDrive
from joints.errors import ConfirmationRequired, StateError
from joints.link.modbus import ModbusLink
from joints.link.trace import Trace
from joints.sim.firmware import Firmware
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.sim.zlac import ZlacFirmware
from joints.transports.loopback import LoopbackTransport
from testdata import VECTORS


class _Profile:
    torque_constant = 0.8


def _sequences() -> dict[str, dict]:
    if not VECTORS.exists():
        pytest.skip(f"manual vectors not found at {VECTORS}")
    return {r["id"]: r for r in json.loads(VECTORS.read_text()) if r.get("record_type") == "sequence"}


def _rig(twin: bool = True) -> tuple[ZlacDrive, ZlacChannelDriver, ZlacChannelDriver, Trace, Firmware]:
    # the twin answers as the drive does (status after enable, quick stop ...): the driver reads
    # back what the drive says, so a plain parameter store only serves register-level checks
    slave = ZlacFirmware(HubMotorProfile(), 1) if twin else Firmware(ZLAC8015D.params)
    trace = Trace()
    link = ModbusLink(LoopbackTransport(ModbusDeviceBus([ModbusFront(slave, ZLAC8015D, 1)])), clock=ManualClock(),
                      trace=trace)
    drive = ZlacDrive(link, 1)
    return drive, ZlacChannelDriver(drive, "left", profile=_Profile()), ZlacChannelDriver(drive, "right", profile=_Profile()), trace, slave


def _frames(trace: Trace) -> list[str]:
    """Frames that write (the driver also reads the targets before enabling: reads change nothing)."""
    return [r.data.hex(" ").upper() for r in trace if r.direction == "tx" and r.data[1] in (0x06, 0x10)]


def _manual(seq_ids: list[str]) -> list[str]:
    seqs = _sequences()
    return [s["send_hex"] for sid in seq_ids for s in seqs[sid]["steps"] if s.get("send_hex")]


def vel_init(d: ZlacDrive, left: ZlacChannelDriver, right: ZlacChannelDriver) -> None:
    d.configure(ControlMode.VELOCITY, acceleration_ms=(500, 500), deceleration_ms=(500, 500))
    left.enable()
    right.enable()


def pos_init(sync: bool) -> Callable[[ZlacDrive, ZlacChannelDriver, ZlacChannelDriver], None]:
    def run(d: ZlacDrive, left: ZlacChannelDriver, right: ZlacChannelDriver) -> None:
        d.configure(ControlMode.RELATIVE_POSITION, acceleration_ms=(500, 500), deceleration_ms=(500, 500),
                    position_speed_rpm=(50, 50), synchronous=sync)
        left.enable()
        right.enable()
    return run


def torque_init(d: ZlacDrive, left: ZlacChannelDriver, right: ZlacChannelDriver) -> None:
    d.configure(ControlMode.TORQUE, torque_rate=(500, 500))
    left.enable()
    right.enable()


CASES = {
    "seq-zlac-3.1-left": (vel_init, lambda d, l, r: (l.set_velocity(1000), l.set_velocity(-1000), d.stop())),
    "seq-zlac-3.1-right": (vel_init, lambda d, l, r: (r.set_velocity(1000), r.set_velocity(-1000), d.stop())),
    "seq-zlac-3.1-sync": (vel_init, lambda d, l, r: (d.set_velocities(100, 100), d.set_velocities(-100, -100), d.stop())),
    "seq-zlac-3.2-left": (pos_init(False), lambda d, l, r: (l.move_by(20480), l.move_by(-20480), d.stop())),
    "seq-zlac-3.2-right": (pos_init(False), lambda d, l, r: (r.move_by(20480), r.move_by(-20480), d.stop())),
    "seq-zlac-3.2-sync": (pos_init(True), lambda d, l, r: (d.move_both(20480, 20480, absolute=False),
                                                          d.move_both(-20480, -20480, absolute=False), d.stop())),
    "seq-zlac-3.4-left": (torque_init, lambda d, l, r: (l.set_current(2000), l.set_current(-2000), d.stop())),
    "seq-zlac-3.4-right": (torque_init, lambda d, l, r: (r.set_current(2000), r.set_current(-2000), d.stop())),
    "seq-zlac-3.4-sync": (torque_init, lambda d, l, r: (d.set_torques(2000, 2000), d.set_torques(-2000, -2000), d.stop())),
}


@pytest.mark.parametrize("seq_id", sorted(CASES))
def test_driver_sends_the_manuals_frames(seq_id: str) -> None:
    seqs = _sequences()
    init, body = CASES[seq_id]
    d, left, right, trace, _slave = _rig()
    init(d, left, right)
    body(d, left, right)
    expected = _manual([seqs[seq_id]["prerequisite"], seq_id])
    ours = _frames(trace)
    # the manual enables once; we enable per wheel, which sends the control word only once
    assert ours == expected


def test_enable_zeroes_stale_targets_first() -> None:
    d, left, right, trace, slave = _rig()
    slave.set("target_velocity_left", 250)  # left over from before a fault
    vel_init(d, left, right)
    writes = _frames(trace)
    zero = "01 10 20 88 00 02 04 00 00 00 00"
    enable = "01 06 20 0E 00 08 E2 0F"
    assert any(w.startswith(zero) for w in writes)
    assert next(i for i, w in enumerate(writes) if w.startswith(zero)) < writes.index(enable)
    assert slave.get("target_velocity_left") == 0


def test_mode_belongs_to_the_drive() -> None:
    d, left, right, _trace, _slave = _rig()
    vel_init(d, left, right)
    with pytest.raises(StateError, match="belongs to the drive"):
        right.set_current(1000)
    right.disable()
    right.enable()
    left.disable()
    right.set_current(500)  # only the right wheel is enabled now: it may switch the drive's mode


def test_state_of_both_wheels_is_one_block_read() -> None:
    d, left, right, trace, slave = _rig(twin=False)
    slave.set("actual_motor_position_left", -20480)
    slave.set("actual_velocity_right", 1000)
    slave.set("error_code_left", 0x0020)
    d.identify()  # once per connection: the encoder lines the drive is set to (0x2030, 0x2060)
    sent = len([r for r in trace if r.direction == "tx"])
    block = d.read_status()
    assert len([r for r in trace if r.direction == "tx"]) == sent + 1
    ls, rs = left.state_from(block, 0.0), right.state_from(block, 0.0)
    assert (ls.position, ls.fault, rs.velocity) == (-20480, 0x0020, 1000)
    assert "Position following error" in left.fault_text(ls.fault)


def test_dangerous_writes_need_confirmation() -> None:
    _d, left, _right, trace, _slave = _rig()
    with pytest.raises(ConfirmationRequired):
        left.reset_zero_point()
    with pytest.raises(ConfirmationRequired):
        left.clear_feedback_position()
    with pytest.raises(ConfirmationRequired):
        left.write("rs485_baud_rate", 2)
    assert len(trace) == 0


def test_a_drive_enabled_by_another_program_is_enabled_in_its_mode() -> None:
    """"Enabled" is what the drive says: a second host (another process) that sent nothing yet finds the
    drive on, in the mode the first one chose, and commands it without switching the mode."""
    d, left, right, _trace, slave = _rig()
    vel_init(d, left, right)
    bus = ModbusDeviceBus([ModbusFront(slave, ZLAC8015D, 1)])
    other = ZlacDrive(ModbusLink(LoopbackTransport(bus), clock=ManualClock()), 1)
    o_left, o_right = (ZlacChannelDriver(other, side, profile=_Profile()) for side in ("left", "right"))
    assert not o_left.is_enabled  # nothing read yet
    s = o_left.state_from(other.read_status(), 0.0)
    assert s.enabled and o_left.is_enabled and o_right.is_enabled
    o_left.set_velocity(500)  # same mode: accepted; the drive's mode register is read, not overwritten
    assert other.state.mode == ControlMode.VELOCITY
    assert ("control_mode", int(ControlMode.VELOCITY)) not in slave.write_log[-3:]
