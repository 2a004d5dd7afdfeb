"""The emulated Modbus slave (eRob register table): answers, exceptions, image and write log."""

from __future__ import annotations

import pytest

from joints.codecs import modbus as mb
from joints.codecs.crc import append_crc
from joints.devices.erob.registers import EROB_MODBUS, STATUS_BLOCK_START, STATUS_BLOCK_WORDS
from joints.devices.registers import Register
from joints.sim.modbus_slave import (
    ILLEGAL_DATA_ADDRESS,
    ILLEGAL_DATA_VALUE,
    ILLEGAL_FUNCTION,
    ModbusDeviceBus,
    ModbusException,
    ModbusSlave,
)

ADDR = 2


def words32(value: int) -> tuple[int, int]:
    raw = value & 0xFFFFFFFF
    return raw >> 16, raw & 0xFFFF


@pytest.fixture
def slave() -> ModbusSlave:
    return ModbusSlave(EROB_MODBUS, ADDR)


def ask(bus: ModbusDeviceBus, request: mb.Message) -> mb.Message | None:
    """Send a request frame to the bus, decode its answer (None if it stays silent)."""
    answer = bus.receive(mb.encode(request))
    if not answer:
        return None
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.feed(answer)
    reply = codec.next_message()
    assert reply is not None and codec.buffered == 0
    return reply


# ------------------------------------------------------------------------------ exceptions


def test_read_unknown_address_is_exception_02(slave: ModbusSlave) -> None:
    assert slave.handle(mb.ReadHoldingRegisters(ADDR, 0x0010, 1)) == mb.ExceptionReply(ADDR, 3, 2)
    assert slave.handle(mb.ReadInputRegisters(ADDR, 0x0010, 1)) == mb.ExceptionReply(ADDR, 4, 2)
    # starting in a gap, or ending past the table, is refused too
    assert slave.handle(mb.ReadHoldingRegisters(ADDR, 0x0062, 1)).code == ILLEGAL_DATA_ADDRESS
    assert slave.handle(mb.ReadHoldingRegisters(ADDR, 0x00F9, 2)).code == ILLEGAL_DATA_ADDRESS
    assert slave.handle(mb.ReadHoldingRegisters(ADDR, 0xFFFF, 2)).code == ILLEGAL_DATA_ADDRESS
    bus = ModbusDeviceBus([slave])
    assert ask(bus, mb.ReadHoldingRegisters(ADDR, 0x0010, 1)) == mb.ExceptionReply(ADDR, 3, 2)


def test_write_read_only_register_is_exception_02(slave: ModbusSlave) -> None:
    before = dict(slave.words)
    assert slave.handle(mb.WriteSingleRegister(ADDR, 0x0060, 1)) == mb.ExceptionReply(ADDR, 6, 2)
    assert slave.handle(mb.WriteMultipleRegisters(ADDR, 0x0060, (1, 0))) == mb.ExceptionReply(ADDR, 16, 2)
    # a block that runs from writable registers into a read-only one is refused as a whole
    assert slave.handle(mb.WriteMultipleRegisters(ADDR, 0x0051, (0, 1, 0))).code == ILLEGAL_DATA_ADDRESS
    assert slave.words == before
    assert slave.write_log == []


def test_write_unknown_address_is_exception_02(slave: ModbusSlave) -> None:
    assert slave.handle(mb.WriteSingleRegister(ADDR, 0x0033, 1)).code == ILLEGAL_DATA_ADDRESS
    assert slave.handle(mb.WriteSingleRegister(ADDR, 0x00F5, 1)).code == ILLEGAL_DATA_ADDRESS


def test_out_of_range_value_is_exception_03_and_image_unchanged(slave: ModbusSlave) -> None:
    slave.set("operation_mode", 2)
    before = dict(slave.words)
    bus = ModbusDeviceBus([slave])
    assert ask(bus, mb.WriteSingleRegister(ADDR, 0x0040, 7)) == mb.ExceptionReply(ADDR, 6, 3)
    assert slave.words == before
    assert slave.get("operation_mode") == 2
    assert slave.write_log == []
    assert slave.handle(mb.WriteSingleRegister(ADDR, 0x0040, 0)).code == ILLEGAL_DATA_VALUE
    assert slave.handle(mb.WriteSingleRegister(ADDR, 0x0000, 0)).code == ILLEGAL_DATA_VALUE  # address 0
    assert slave.handle(mb.WriteSingleRegister(ADDR, 0x0002, 4001)).code == ILLEGAL_DATA_VALUE
    assert slave.words == before


def test_refused_block_write_is_atomic(slave: ModbusSlave) -> None:
    """FC16 over operation_mode (valid 3) and motion_mode (invalid 9): nothing is applied or logged."""
    calls: list[str] = []

    class Hooked(ModbusSlave):
        def on_write(self, reg: Register, value: int) -> None:
            calls.append(reg.name)

    s = Hooked(EROB_MODBUS, ADDR)
    before = dict(s.words)
    reply = s.handle(mb.WriteMultipleRegisters(ADDR, 0x0040, (3, 9)))
    assert reply == mb.ExceptionReply(ADDR, 16, ILLEGAL_DATA_VALUE)
    assert s.words == before
    assert s.write_log == []
    assert calls == []  # no command side effect for a refused write


def test_block_write_of_zero_registers_is_exception_03(slave: ModbusSlave) -> None:
    # a device decodes "write 0 registers" (the host encoder refuses it); Modbus answers 03
    bus = ModbusDeviceBus([slave])
    answer = bus.receive(append_crc(bytes.fromhex("02 10 00 40 00 00 00")))
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.feed(answer)
    assert codec.next_message() == mb.ExceptionReply(ADDR, 16, ILLEGAL_DATA_VALUE)
    assert slave.write_log == []


def test_read_quantity_out_of_range_is_exception_03(slave: ModbusSlave) -> None:
    bus = ModbusDeviceBus([slave])
    for count in (0, mb.MAX_READ + 1):
        answer = bus.receive(append_crc(bytes((ADDR, 3, 0, 0x60)) + count.to_bytes(2, "big")))
        codec = mb.ModbusRtuCodec(mb.Role.HOST)
        codec.feed(answer)
        assert codec.next_message() == mb.ExceptionReply(ADDR, 3, ILLEGAL_DATA_VALUE)


def test_unsupported_function_is_exception_01(slave: ModbusSlave) -> None:
    bus = ModbusDeviceBus([slave])
    answer = bus.receive(append_crc(bytes.fromhex("02 01 00 00 00 08")))  # FC01 read coils
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.feed(answer)
    assert codec.next_message() == mb.ExceptionReply(ADDR, 1, ILLEGAL_FUNCTION)


def test_on_write_refusal_restores_image() -> None:
    class Refusing(ModbusSlave):
        def on_write(self, reg: Register, value: int) -> None:
            if reg.name == "target_speed" and value < 0:
                raise ModbusException(0x04, "refuses to turn backwards")

    s = Refusing(EROB_MODBUS, ADDR)
    s.set("target_speed", 5)
    before = dict(s.words)
    assert s.handle(mb.WriteMultipleRegisters(ADDR, 0x0051, words32(-10))) == mb.ExceptionReply(ADDR, 16, 0x04)
    assert s.words == before and s.get("target_speed") == 5


# ---------------------------------------------------------------------------------- reads


def test_status_block_read_with_gaps(slave: ModbusSlave) -> None:
    assert STATUS_BLOCK_START == 0x0060 and STATUS_BLOCK_WORDS == 25
    slave.set("error_code", 0x0FA2)
    slave.set("motion_status", 1)
    slave.set("status_of_achieving_position", 4)
    slave.set("actual_position", -5)
    slave.set("bus_voltage", 48000)
    slave.set("part_of_power_temperature", -3)
    # scribble into the gaps: they must still read 0
    for gap in (0x0062, 0x006A, 0x006B):
        slave.words[gap] = 0xBEEF

    bus = ModbusDeviceBus([slave])
    reply = ask(bus, mb.ReadHoldingRegisters(ADDR, STATUS_BLOCK_START, STATUS_BLOCK_WORDS))
    assert isinstance(reply, mb.ReadRegistersReply)
    values = reply.values
    assert len(values) == 25

    def at(address: int) -> int:
        return values[address - STATUS_BLOCK_START]

    assert at(0x0060) == 0x0FA2
    assert at(0x0061) == 1
    assert at(0x0062) == 0 and at(0x006A) == 0 and at(0x006B) == 0
    assert at(0x0063) == 4
    assert (at(0x0066), at(0x0067)) == (0xFFFF, 0xFFFB)  # -5, Hi word first
    assert (at(0x0076), at(0x0077)) == words32(48000)
    assert at(0x0078) == 0xFFFD  # int16 -3


def test_command_registers_read_zero(slave: ModbusSlave) -> None:
    assert slave.handle(mb.WriteSingleRegister(ADDR, 0x00F0, 1)) == mb.WriteSingleRegisterReply(ADDR, 0x00F0, 1)
    assert slave.handle(mb.ReadHoldingRegisters(ADDR, 0x00F0, 1)) == mb.ReadRegistersReply(ADDR, 3, (0,))
    assert slave.write_log == [("enable_the_motor", 1)]


# --------------------------------------------------------------------------------- writes


def test_int32_write_via_fc16_round_trip(slave: ModbusSlave) -> None:
    bus = ModbusDeviceBus([slave])
    hi, lo = words32(-500000)
    assert ask(bus, mb.WriteMultipleRegisters(ADDR, 0x0043, (hi, lo))) == (
        mb.WriteMultipleRegistersReply(ADDR, 0x0043, 2)
    )
    assert slave.get("target_absolute_position") == -500000
    assert slave.words[0x0043] == hi and slave.words[0x0044] == lo
    assert ask(bus, mb.ReadHoldingRegisters(ADDR, 0x0043, 2)) == mb.ReadRegistersReply(ADDR, 3, (hi, lo))

    # the manual's frame: 500000 = 0x0007A120 to target absolute position of slave 2
    answer = bus.receive(bytes.fromhex("02 10 00 43 00 02 04 00 07 A1 20 71 47"))
    assert answer == bytes.fromhex("02 10 00 43 00 02 B0 2F")
    assert slave.get("target_absolute_position") == 500000

    # two int32 registers in one block
    ask(bus, mb.WriteMultipleRegisters(ADDR, 0x0049, words32(100000) + words32(-1)))
    assert slave.get("profile_acceleration") == 100000
    assert slave.get("profile_deceleration") == -1


def test_write_log_records_typed_values(slave: ModbusSlave) -> None:
    slave.handle(mb.WriteSingleRegister(ADDR, 0x0040, 3))
    slave.handle(mb.WriteMultipleRegisters(ADDR, 0x0051, words32(-10000)))
    slave.handle(mb.WriteMultipleRegisters(ADDR, 0x0047, words32(10000) + words32(20000)))
    slave.handle(mb.WriteSingleRegister(ADDR, 0x0040, 9))  # refused: not logged
    slave.handle(mb.WriteSingleRegister(ADDR, 0x00F1, 1))
    assert slave.write_log == [
        ("operation_mode", 3),
        ("target_speed", -10000),
        ("profile_speed", 10000),
        ("profile_acceleration", 20000),
        ("start_operating", 1),
    ]


def test_initial_values_and_set_saturates() -> None:
    s = ModbusSlave(EROB_MODBUS, 1, values={"operation_mode": 3, "actual_position": -7})
    assert s.get("operation_mode") == 3 and s.get("actual_position") == -7
    assert s.get(0x0066) == -7
    s.set("part_of_power_temperature", 100000)
    assert s.get("part_of_power_temperature") == 0x7FFF
    assert s.write_log == []  # the device's own updates are not bus writes


# ------------------------------------------------------------------------------------ bus


def test_bus_dispatch_broadcast_and_silence() -> None:
    a, b = ModbusSlave(EROB_MODBUS, 1), ModbusSlave(EROB_MODBUS, 2)
    bus = ModbusDeviceBus([a, b])
    with pytest.raises(ValueError):
        bus.add(ModbusSlave(EROB_MODBUS, 2))
    assert ask(bus, mb.WriteSingleRegister(0, 0x0040, 2)) is None  # broadcast: nobody answers
    assert a.get("operation_mode") == b.get("operation_mode") == 2
    assert ask(bus, mb.ReadHoldingRegisters(0, 0x0040, 1)) is None  # broadcast read ignored
    assert ask(bus, mb.ReadHoldingRegisters(9, 0x0040, 1)) is None  # nobody at 9
    assert ask(bus, mb.ReadHoldingRegisters(1, 0x0040, 1)) == mb.ReadRegistersReply(1, 3, (2,))


def test_bus_stays_silent_on_corrupt_frame_and_recovers() -> None:
    s = ModbusSlave(EROB_MODBUS, ADDR)
    bus = ModbusDeviceBus([s])
    good = mb.encode(mb.ReadHoldingRegisters(ADDR, 0x0040, 1))
    bad = bytearray(good)
    bad[-2] ^= 0x40
    assert bus.receive(bytes(bad)) == b""
    assert bus.frame_errors >= 1
    answer = bus.receive(good)
    assert answer == mb.encode(mb.ReadRegistersReply(ADDR, 3, (0,)))
    # a truncated request is dropped at silence
    assert bus.receive(good[:5]) == b""
    assert bus.silence() == b""
    assert bus.receive(good) == answer


def test_bus_answers_requests_fed_byte_by_byte() -> None:
    bus = ModbusDeviceBus([ModbusSlave(EROB_MODBUS, ADDR)])
    frame = mb.encode(mb.WriteSingleRegister(ADDR, 0x0041, 2))
    out = b"".join(bus.receive(frame[i : i + 1]) for i in range(len(frame)))
    assert out == frame  # FC06 reply echoes the request
