"""Each documented eRob procedure (Modbus manual v1.6, chapters 5 and 7) reproduced by the driver.

The manual's step tables (vectors.json sequences, corrected frames) give the registers written
and the order in which they take effect. Settings written between two commands take effect
together at the next command, so we compare, segment by segment: the settings (name, value)
written before each command, and the commands themselves in order. Contiguous settings may be
batched into one FC16 by the driver.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence

import pytest

from joints.clock import ManualClock
from joints.codecs import modbus as mb
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.erob.registers import EROB_MODBUS, MotionMode, MotionStatus
from joints.drivers.erob_modbus import ENABLE_SETTLE, ErobModbusDriver
from joints.errors import ConfirmationRequired
from joints.link.modbus import ModbusLink
from joints.link.trace import Trace
from joints.sim.firmware import Firmware
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.transports.loopback import LoopbackTransport
from testdata import VECTORS

COMMANDS = {
    "enable_the_motor",
    "start_operating",
    "stop_operating",
    "emergency_stop",
    "stop_repetitive_motion",
    "clear_errors",
    "save_parameters",
    "reset_output_encoder",
}

Segment = tuple[frozenset[tuple[str, int]], tuple[str, int] | None]


def _sequences() -> dict[str, dict]:
    if not VECTORS.exists():
        pytest.skip(f"manual vectors not found at {VECTORS}")
    data = json.loads(VECTORS.read_text())
    return {r["id"]: r for r in data if r.get("record_type") == "sequence"}


def _writes_of_frame(frame: bytes) -> list[tuple[str, int]]:
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    codec.feed(frame)
    msg = codec.next_message()
    if isinstance(msg, mb.WriteSingleRegister):
        start, words = msg.address, (msg.value,)
    elif isinstance(msg, mb.WriteMultipleRegisters):
        start, words = msg.address, msg.values
    else:
        return []
    return list(EROB_MODBUS.decode_block(start, words).items())


def segments(writes: list[tuple[str, int]]) -> list[Segment]:
    out: list[Segment] = []
    pending: set[tuple[str, int]] = set()
    for name, value in writes:
        if name in COMMANDS:
            out.append((frozenset(pending), (name, value)))
            pending = set()
        else:
            pending.add((name, value))
    if pending:
        out.append((frozenset(pending), None))
    return out


def manual_segments(seq: dict) -> list[Segment]:
    writes: list[tuple[str, int]] = []
    for step in seq["steps"]:
        if "send_hex" in step:
            writes += _writes_of_frame(bytes.fromhex(step["send_hex"]))
    return segments(writes)


class ScriptedErob(Firmware):
    """A parameter store whose achieving-position status follows "Enable the Motor"."""

    def __init__(self) -> None:
        super().__init__(EROB_PARAMS)

    def on_write(self, name: str, value: int) -> None:
        if name == "enable_the_motor":
            self.set("status_of_achieving_position", 1 if value else 0)


class CalibrationSlave(Firmware):
    """Scripted drive for chapter 7: actual position = encoder position + position offset."""

    def __init__(self, encoder: int) -> None:
        super().__init__(EROB_PARAMS)
        self.encoder = encoder
        self.saved_parameters = False

    def on_read(self, names: Sequence[str]) -> None:
        self.set("actual_position", self.encoder + self.get("position_offset"))

    def on_write(self, name: str, value: int) -> None:
        if name == "reset_output_encoder":
            self.encoder %= 524288
        if name == "save_parameters":
            self.saved_parameters = True


def _rig(slave_id: int, slave: Firmware | None = None):  # type: ignore[no-untyped-def]
    slave = slave or ScriptedErob()
    clock = ManualClock()
    trace = Trace()
    link = ModbusLink(LoopbackTransport(ModbusDeviceBus([ModbusFront(slave, EROB_MODBUS, slave_id)])), clock=clock,
                      trace=trace)
    return ErobModbusDriver(link, slave_id, clock=clock), slave, trace


def _abs(d: ErobModbusDriver) -> None:
    d.configure_position(MotionMode.ABSOLUTE, speed=10000, acceleration=10000, deceleration=10000, clear_relative=True)
    d.enable()
    d.move_to(500000)
    d.state()
    d.disable()


def _rel(d: ErobModbusDriver) -> None:
    d.configure_position(MotionMode.ABSOLUTE, speed=10000, acceleration=10000, deceleration=10000)
    d.enable()
    d.move_by(100000)
    d.state()
    d.disable()


def _cont(d: ErobModbusDriver) -> None:
    d.configure_position(MotionMode.CONTINUOUS, speed=10000, acceleration=10000, deceleration=10000)
    d.enable()
    d.move_continuous(10000)
    d.state()
    d.stop()
    d.disable()


def _rep(d: ErobModbusDriver) -> None:
    d.configure_position(MotionMode.REPETITIVE, speed=10000, acceleration=10000, deceleration=10000, dwell=20000)
    d.enable()
    d.move_repetitive(200000)
    d.state()
    d.stop_repetitive()
    d.disable()


def _speed(d: ErobModbusDriver) -> None:
    d.configure_velocity(acceleration=10000, deceleration=10000)
    d.enable()
    d.set_velocity(10000)
    d.state()
    d.set_velocity(0)
    d.disable()


def _torque(d: ErobModbusDriver) -> None:
    d.configure_torque(max_speed=0)
    d.enable()
    d.set_current(1000)
    d.state()
    d.disable()


PROCEDURES: dict[str, tuple[int, Callable[[ErobModbusDriver], None]]] = {
    "seq-erob-modbus-en-5.1.1": (2, _abs),
    "seq-erob-modbus-en-5.1.2": (2, _rel),
    "seq-erob-modbus-en-5.1.3": (2, _cont),
    "seq-erob-modbus-en-5.1.4": (2, _rep),
    "seq-erob-modbus-en-5.2": (1, _speed),
    "seq-erob-modbus-en-5.3": (1, _torque),
}


@pytest.mark.parametrize("seq_id", sorted(PROCEDURES))
def test_chapter5_procedure(seq_id: str) -> None:
    seq = _sequences()[seq_id]
    slave_id, script = PROCEDURES[seq_id]
    driver, slave, _trace = _rig(slave_id)
    script(driver)
    assert segments(slave.write_log) == manual_segments(seq)


@pytest.mark.parametrize("seq_id", sorted(PROCEDURES))
def test_motion_waits_500ms_after_enable(seq_id: str) -> None:
    slave_id, script = PROCEDURES[seq_id]
    driver, _slave, trace = _rig(slave_id)
    script(driver)
    tx = [r for r in trace if r.direction == "tx"]
    i = next(i for i, r in enumerate(tx) if r.data[1] == 0x06 and r.data[2:6] == bytes.fromhex("00F00001"))
    enable_t = tx[i].time
    after = [r for r in tx[i + 1 :] if r.data[1] in (0x06, 0x10)]
    # the first write after "enable" that makes the motor move comes >= 500 ms later
    motion = [r for r in after if r.data[2:4] in (bytes.fromhex("00F1"), bytes.fromhex("0051"), bytes.fromhex("004F"),
                                                     bytes.fromhex("0045"))]
    assert motion, "no motion command was sent"
    assert motion[0].time - enable_t >= ENABLE_SETTLE - 1e-12


@pytest.mark.parametrize("seq_id,multi", [("seq-erob-modbus-en-7.2", False), ("seq-erob-modbus-en-7.3", True)])
def test_chapter7_zero_calibration(seq_id: str, multi: bool) -> None:
    seq = _sequences()[seq_id]
    slave = CalibrationSlave(encoder=10000)
    driver, _, _trace = _rig(2, slave)
    result = driver.calibrate_zero(multi_turn=multi, confirm=True)
    assert (result.actual_position, result.position_offset, result.saved) == (10000, 252144, True)
    assert segments(slave.write_log) == manual_segments(seq)
    assert slave.saved_parameters
    # after the offset the drive reads 262144 at the calibrated zero (the manual's final step)
    assert driver.read("actual_position") == 262144


def test_calibration_needs_confirmation_and_writes_nothing_without() -> None:
    slave = CalibrationSlave(encoder=10000)
    driver, _, trace = _rig(2, slave)
    with pytest.raises(ConfirmationRequired):
        driver.calibrate_zero()
    with pytest.raises(ConfirmationRequired):
        driver.save_parameters()
    with pytest.raises(ConfirmationRequired):
        driver.reset_output_encoder()
    with pytest.raises(ConfirmationRequired):
        driver.write("modbus_baud_rate", 4)
    assert slave.write_log == []
    assert len(trace) == 0


class StartingDrive(Firmware):
    """A parameter store whose motion status follows "start operating", as a real drive's does."""

    def __init__(self, address: int) -> None:
        super().__init__(EROB_PARAMS)
        self.front = ModbusFront(self, EROB_MODBUS, address)

    def on_write(self, name: str, value: int) -> None:
        if name == "start_operating":
            self.set("motion_status", int(MotionStatus.MOVING))


def test_start_is_never_retried_blindly() -> None:
    """A lost reply to "start operating" must not start a (relative) motion twice: the driver reads
    back whether the drive started, and it did, so nothing is sent again."""
    calls = []
    bus = ModbusDeviceBus([StartingDrive(2).front])

    def flaky(data: bytes) -> bytes:
        calls.append(data)
        reply = bus.receive(data)
        if data[2:4] == bytes.fromhex("00F1"):
            return b""  # reply lost
        return reply

    clock = ManualClock()
    link = ModbusLink(LoopbackTransport(flaky), clock=clock)
    d = ErobModbusDriver(link, 2, clock=clock)
    d.enable()
    d.move_by(1000)
    assert sum(1 for c in calls if c[2:4] == bytes.fromhex("00F1")) == 1


def test_start_lost_on_the_way_is_sent_again_after_reading_back() -> None:
    """The request itself was lost (the drive never saw it): the read-back says not started, so the
    driver sends it once more - and only once."""
    calls = []
    drive = StartingDrive(2)
    bus = ModbusDeviceBus([drive.front])
    lost = []

    def flaky(data: bytes) -> bytes:
        calls.append(data)
        if data[2:4] == bytes.fromhex("00F1") and not lost:
            lost.append(data)
            return b""  # the frame never reached the drive
        return bus.receive(data)

    clock = ManualClock()
    d = ErobModbusDriver(ModbusLink(LoopbackTransport(flaky), clock=clock), 2, clock=clock)
    d.enable()
    d.move_by(1000)
    assert sum(1 for c in calls if c[2:4] == bytes.fromhex("00F1")) == 2
    assert drive.write_log.count(("start_operating", 1)) == 1  # executed exactly once
