"""The Modbus front over a firmware (eRob register table): answers, exceptions, image and write log."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import pytest

from joints.codecs import modbus as mb
from joints.codecs.crc import append_crc
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.erob.registers import EROB_MODBUS, STATUS_BLOCK_START, STATUS_BLOCK_WORDS
from joints.devices.params import Access, ParamSet
from joints.devices.registers import Register, RegisterTable
from joints.errors import ParameterRefused, Refusal
from joints.sim.firmware import Firmware
from joints.sim.modbus_front import (
    EXCEPTION_FOR,
    ILLEGAL_DATA_ADDRESS,
    ILLEGAL_DATA_VALUE,
    ILLEGAL_FUNCTION,
    ModbusDeviceBus,
    ModbusFront,
)

ADDR = 2


def words32(value: int) -> tuple[int, int]:
    raw = value & 0xFFFFFFFF
    return raw >> 16, raw & 0xFFFF


@pytest.fixture
def slave() -> ModbusFront:
    return ModbusFront(Firmware(EROB_PARAMS), EROB_MODBUS, ADDR)


def code(reply: mb.Message | None) -> int:
    """The exception code of an exception reply."""
    assert isinstance(reply, mb.ExceptionReply), reply
    return reply.code


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


def test_read_unknown_address_is_exception_02(slave: ModbusFront) -> None:
    assert slave.handle(mb.ReadHoldingRegisters(ADDR, 0x0010, 1)) == mb.ExceptionReply(ADDR, 3, 2)
    assert slave.handle(mb.ReadInputRegisters(ADDR, 0x0010, 1)) == mb.ExceptionReply(ADDR, 4, 2)
    # starting in a gap, or ending past the table, is refused too
    assert code(slave.handle(mb.ReadHoldingRegisters(ADDR, 0x0062, 1))) == ILLEGAL_DATA_ADDRESS
    assert code(slave.handle(mb.ReadHoldingRegisters(ADDR, 0x00F9, 2))) == ILLEGAL_DATA_ADDRESS
    assert code(slave.handle(mb.ReadHoldingRegisters(ADDR, 0xFFFF, 2))) == ILLEGAL_DATA_ADDRESS
    bus = ModbusDeviceBus([slave])
    assert ask(bus, mb.ReadHoldingRegisters(ADDR, 0x0010, 1)) == mb.ExceptionReply(ADDR, 3, 2)


def test_write_read_only_register_is_exception_02(slave: ModbusFront) -> None:
    before = slave.image()
    assert slave.handle(mb.WriteSingleRegister(ADDR, 0x0060, 1)) == mb.ExceptionReply(ADDR, 6, 2)
    assert slave.handle(mb.WriteMultipleRegisters(ADDR, 0x0060, (1, 0))) == mb.ExceptionReply(ADDR, 16, 2)
    # a block that runs from writable registers into a read-only one is refused as a whole
    assert code(slave.handle(mb.WriteMultipleRegisters(ADDR, 0x0051, (0, 1, 0)))) == ILLEGAL_DATA_ADDRESS
    assert slave.image() == before
    assert slave.firmware.write_log == []


def test_write_unknown_address_is_exception_02(slave: ModbusFront) -> None:
    assert code(slave.handle(mb.WriteSingleRegister(ADDR, 0x0033, 1))) == ILLEGAL_DATA_ADDRESS
    assert code(slave.handle(mb.WriteSingleRegister(ADDR, 0x00F5, 1))) == ILLEGAL_DATA_ADDRESS


def test_out_of_range_value_is_exception_03_and_image_unchanged(slave: ModbusFront) -> None:
    slave.firmware.set("operation_mode", 2)
    before = slave.image()
    bus = ModbusDeviceBus([slave])
    assert ask(bus, mb.WriteSingleRegister(ADDR, 0x0040, 7)) == mb.ExceptionReply(ADDR, 6, 3)
    assert slave.image() == before
    assert slave.firmware.get("operation_mode") == 2
    assert slave.firmware.write_log == []
    assert code(slave.handle(mb.WriteSingleRegister(ADDR, 0x0040, 0))) == ILLEGAL_DATA_VALUE
    assert code(slave.handle(mb.WriteSingleRegister(ADDR, 0x0000, 0))) == ILLEGAL_DATA_VALUE  # address 0
    assert code(slave.handle(mb.WriteSingleRegister(ADDR, 0x0002, 4001))) == ILLEGAL_DATA_VALUE
    assert slave.image() == before


def test_refused_block_write_is_atomic() -> None:
    """FC16 over operation_mode (valid 3) and motion_mode (invalid 9): nothing is applied or logged."""
    calls: list[str] = []

    class Hooked(Firmware):
        def on_write(self, name: str, value: int) -> None:
            calls.append(name)

    s = ModbusFront(Hooked(EROB_PARAMS), EROB_MODBUS, ADDR)
    before = s.image()
    reply = s.handle(mb.WriteMultipleRegisters(ADDR, 0x0040, (3, 9)))
    assert reply == mb.ExceptionReply(ADDR, 16, ILLEGAL_DATA_VALUE)
    assert s.image() == before
    assert s.firmware.write_log == []
    assert calls == []  # no command side effect for a refused write


def test_block_write_of_zero_registers_is_exception_03(slave: ModbusFront) -> None:
    # a device decodes "write 0 registers" (the host encoder refuses it); Modbus answers 03
    bus = ModbusDeviceBus([slave])
    answer = bus.receive(append_crc(bytes.fromhex("02 10 00 40 00 00 00")))
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.feed(answer)
    assert codec.next_message() == mb.ExceptionReply(ADDR, 16, ILLEGAL_DATA_VALUE)
    assert slave.firmware.write_log == []


def test_read_quantity_out_of_range_is_exception_03(slave: ModbusFront) -> None:
    bus = ModbusDeviceBus([slave])
    for count in (0, mb.MAX_READ + 1):
        answer = bus.receive(append_crc(bytes((ADDR, 3, 0, 0x60)) + count.to_bytes(2, "big")))
        codec = mb.ModbusRtuCodec(mb.Role.HOST)
        codec.feed(answer)
        assert codec.next_message() == mb.ExceptionReply(ADDR, 3, ILLEGAL_DATA_VALUE)


def test_unsupported_function_is_exception_01(slave: ModbusFront) -> None:
    bus = ModbusDeviceBus([slave])
    answer = bus.receive(append_crc(bytes.fromhex("02 01 00 00 00 08")))  # FC01 read coils
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.feed(answer)
    assert codec.next_message() == mb.ExceptionReply(ADDR, 1, ILLEGAL_FUNCTION)


def test_refusal_in_this_state_is_exception_03_and_changes_nothing() -> None:
    calls: list[str] = []

    class Refusing(Firmware):
        def check_write(self, name: str, value: int) -> None:
            if name == "target_speed" and value < 0:
                raise ParameterRefused(Refusal.STATE, name, "refuses to turn backwards")

        def on_write(self, name: str, value: int) -> None:
            calls.append(name)

    s = ModbusFront(Refusing(EROB_PARAMS), EROB_MODBUS, ADDR)
    s.firmware.set("target_speed", 5)
    before = s.image()
    # a block of two settings and the refused target: nothing of it is applied
    block = words32(100) + words32(-10)
    assert s.handle(mb.WriteMultipleRegisters(ADDR, 0x004F, block)) == mb.ExceptionReply(ADDR, 16, ILLEGAL_DATA_VALUE)
    assert s.image() == before and s.firmware.get("target_speed") == 5 and s.firmware.get("target_current") == 0
    assert calls == [] and s.firmware.write_log == []


# ---------------------------------------------------------------------------------- reads


def test_status_block_read_with_gaps(slave: ModbusFront) -> None:
    assert STATUS_BLOCK_START == 0x0060 and STATUS_BLOCK_WORDS == 25
    fw = slave.firmware
    fw.set("error_code", 0x0FA2)
    fw.set("motion_status", 1)
    fw.set("status_of_achieving_position", 4)
    fw.set("actual_position", -5)
    fw.set("bus_voltage", 48000)
    fw.set("part_of_power_temperature", -3)

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


def test_command_registers_read_zero(slave: ModbusFront) -> None:
    assert slave.handle(mb.WriteSingleRegister(ADDR, 0x00F0, 1)) == mb.WriteSingleRegisterReply(ADDR, 0x00F0, 1)
    assert slave.handle(mb.ReadHoldingRegisters(ADDR, 0x00F0, 1)) == mb.ReadRegistersReply(ADDR, 3, (0,))
    assert slave.firmware.write_log == [("enable_the_motor", 1)]


# --------------------------------------------------------------------------------- writes


def test_int32_write_via_fc16_round_trip(slave: ModbusFront) -> None:
    bus = ModbusDeviceBus([slave])
    fw = slave.firmware
    hi, lo = words32(-500000)
    assert ask(bus, mb.WriteMultipleRegisters(ADDR, 0x0043, (hi, lo))) == (
        mb.WriteMultipleRegistersReply(ADDR, 0x0043, 2)
    )
    assert fw.get("target_absolute_position") == -500000
    assert slave.image()[0x0043] == hi and slave.image()[0x0044] == lo
    assert ask(bus, mb.ReadHoldingRegisters(ADDR, 0x0043, 2)) == mb.ReadRegistersReply(ADDR, 3, (hi, lo))

    # the manual's frame: 500000 = 0x0007A120 to target absolute position of slave 2
    answer = bus.receive(bytes.fromhex("02 10 00 43 00 02 04 00 07 A1 20 71 47"))
    assert answer == bytes.fromhex("02 10 00 43 00 02 B0 2F")
    assert fw.get("target_absolute_position") == 500000

    # two int32 registers in one block
    ask(bus, mb.WriteMultipleRegisters(ADDR, 0x0049, words32(100000) + words32(-1)))
    assert fw.get("profile_acceleration") == 100000
    assert fw.get("profile_deceleration") == -1


def test_write_log_records_typed_values(slave: ModbusFront) -> None:
    slave.handle(mb.WriteSingleRegister(ADDR, 0x0040, 3))
    slave.handle(mb.WriteMultipleRegisters(ADDR, 0x0051, words32(-10000)))
    slave.handle(mb.WriteMultipleRegisters(ADDR, 0x0047, words32(10000) + words32(20000)))
    slave.handle(mb.WriteSingleRegister(ADDR, 0x0040, 9))  # refused: not logged
    slave.handle(mb.WriteSingleRegister(ADDR, 0x00F1, 1))
    assert slave.firmware.write_log == [
        ("operation_mode", 3),
        ("target_speed", -10000),
        ("profile_speed", 10000),
        ("profile_acceleration", 20000),
        ("start_operating", 1),
    ]


def test_initial_values_and_set_saturates() -> None:
    front = ModbusFront.plain(EROB_MODBUS, 1, values={"operation_mode": 3, "actual_position": -7})
    s = front.firmware
    assert s.get("operation_mode") == 3 and s.get("actual_position") == -7
    assert front.read(0x0066, 2) == (0xFFFF, 0xFFF9)
    s.set("part_of_power_temperature", 100000)
    assert s.get("part_of_power_temperature") == 0x7FFF
    assert s.write_log == []  # the device's own updates are not bus writes


# ------------------------------------------------------------------------------------ bus


def test_bus_dispatch_broadcast_and_silence() -> None:
    a, b = ModbusFront.plain(EROB_MODBUS, 1), ModbusFront.plain(EROB_MODBUS, 2)
    bus = ModbusDeviceBus([a, b])
    with pytest.raises(ValueError):
        bus.add(ModbusFront.plain(EROB_MODBUS, 2))
    assert ask(bus, mb.WriteSingleRegister(0, 0x0040, 2)) is None  # broadcast: nobody answers
    assert a.firmware.get("operation_mode") == b.firmware.get("operation_mode") == 2
    assert ask(bus, mb.ReadHoldingRegisters(0, 0x0040, 1)) is None  # broadcast read ignored
    assert ask(bus, mb.ReadHoldingRegisters(9, 0x0040, 1)) is None  # nobody at 9
    assert ask(bus, mb.ReadHoldingRegisters(1, 0x0040, 1)) == mb.ReadRegistersReply(1, 3, (2,))


def test_bus_stays_silent_on_corrupt_frame_and_recovers() -> None:
    bus = ModbusDeviceBus([ModbusFront.plain(EROB_MODBUS, ADDR)])
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
    bus = ModbusDeviceBus([ModbusFront.plain(EROB_MODBUS, ADDR)])
    frame = mb.encode(mb.WriteSingleRegister(ADDR, 0x0041, 2))
    out = b"".join(bus.receive(frame[i : i + 1]) for i in range(len(frame)))
    assert out == frame  # FC06 reply echoes the request


# ------------------------------------------------------------------- front over a firmware


class Counting(Firmware):
    """Counts frames and which parameters a read asked for; ``actual_position`` is computed."""

    def __init__(self) -> None:
        super().__init__(EROB_PARAMS, values={"modbus_address": ADDR})
        self.frames = 0
        self.asked: list[tuple[str, ...]] = []
        self.position = -5
        self.computed["actual_position"] = lambda: self.position

    def frame_received(self) -> None:
        self.frames += 1

    def on_read(self, names: Sequence[str]) -> None:
        self.asked.append(tuple(names))


def test_a_read_asks_the_firmware_for_the_block_only() -> None:
    fw = Counting()
    front = ModbusFront(fw, EROB_MODBUS, ADDR)
    assert front.read(0x0066, 2) == words32(-5)
    fw.position = 70000
    assert front.read(0x0064, 6) == (0, 0) + words32(70000) + (0, 0)
    assert front.read(0x0041, 1) == (0,)
    assert fw.asked == [("actual_position",), ("given_position", "actual_position", "position_error"),
                        ("motion_mode",)]


def test_block_ends_inside_a_pair_serve_that_word() -> None:
    fw = Counting()
    front = ModbusFront(fw, EROB_MODBUS, ADDR)
    fw.set("target_absolute_position", 0x12345678)
    fw.set("target_relative_position", -2)
    assert front.read(0x0044, 2) == (0x5678, 0xFFFF)  # Lo of one pair, Hi of the next
    # a single word into a pair merges with the pair's other word
    assert front.handle(mb.WriteSingleRegister(ADDR, 0x0043, 0x0001)) == mb.WriteSingleRegisterReply(ADDR, 0x43, 1)
    assert fw.get("target_absolute_position") == 0x00015678
    front.write(0x0044, (0xBEEF, 0x0000))  # Lo of target_absolute_position, Hi of target_relative_position
    assert fw.get("target_absolute_position") == 0x0001BEEF and fw.get("target_relative_position") == 0xFFFE
    assert fw.write_log[-2:] == [("target_absolute_position", 0x0001BEEF), ("target_relative_position", 0xFFFE)]


def test_frame_received_for_own_frames_and_broadcast_writes_only() -> None:
    a, b = Counting(), Counting()
    bus = ModbusDeviceBus([ModbusFront(a, EROB_MODBUS, 1), ModbusFront(b, EROB_MODBUS, 2)])
    ask(bus, mb.ReadHoldingRegisters(1, 0x0040, 1))
    ask(bus, mb.ReadHoldingRegisters(1, 0x0010, 1))  # an exception reply is a frame received too
    ask(bus, mb.WriteSingleRegister(0, 0x0040, 2))  # broadcast write: every drive
    ask(bus, mb.ReadHoldingRegisters(0, 0x0040, 1))  # broadcast read: nobody
    bad = bytearray(mb.encode(mb.ReadHoldingRegisters(2, 0x0040, 1)))
    bad[-1] ^= 1
    bus.receive(bytes(bad))  # corrupt: not received
    assert (a.frames, b.frames) == (3, 1)


def test_address_from_the_node_id_held_at_power_on() -> None:
    fw = Firmware(EROB_PARAMS, values={"modbus_address": 7})
    front = ModbusFront(fw, EROB_MODBUS, node_id="modbus_address")
    assert front.address == 7
    front.write(0x0000, (9,))
    assert front.address == 7  # takes effect after a power cycle, as on the drive
    fw.save(["modbus_address"])
    fw.power_cycle()
    assert front.address == 9 and ModbusDeviceBus([front]).slaves == {9: front}
    with pytest.raises(ValueError):
        ModbusFront(fw, EROB_MODBUS)
    with pytest.raises(ValueError):
        ModbusFront(fw, EROB_MODBUS, 1, node_id="modbus_address")


def test_every_refusal_has_an_exception_code_and_not_readable_is_02() -> None:
    assert set(EXCEPTION_FOR) == set(Refusal)

    class WriteOnlyTarget(Firmware):
        def __init__(self) -> None:
            base = EROB_PARAMS
            params = ParamSet(base.device, (dataclasses.replace(p, access=Access.W) if p.name == "target_speed" else p
                                            for p in base))
            super().__init__(params)

    front = ModbusFront(WriteOnlyTarget(), EROB_MODBUS, ADDR)
    assert front.handle(mb.ReadHoldingRegisters(ADDR, 0x0051, 2)) == mb.ExceptionReply(ADDR, 3, ILLEGAL_DATA_ADDRESS)
    assert front.handle(mb.WriteMultipleRegisters(ADDR, 0x0051, words32(5))) == mb.WriteMultipleRegistersReply(
        ADDR, 0x0051, 2)


def test_a_table_the_firmware_does_not_know_is_refused() -> None:
    from joints.devices.zlac.registers import ZLAC8015D

    with pytest.raises(ValueError, match="not parameters"):
        ModbusFront(Firmware(EROB_PARAMS), ZLAC8015D, 1)


def test_low_word_first_pairs_and_values_outside_the_register_type() -> None:
    table = RegisterTable.build("toy", (
        Register(0x0010, "counter", "int32", low_word_first=True),
        Register(0x0012, "flags"),
        Register(0x0014, "wide", "int32"),
    ))
    front = ModbusFront.plain(table, 1)
    fw = front.firmware
    front.write(0x0010, (0x5678, 0x1234))  # Lo first
    assert fw.get("counter") == 0x12345678
    fw.set("flags", 7)
    assert front.read(0x0010, 3) == (0x5678, 0x1234, 7)
    assert front.read(0x0011, 1) == (0x1234,)  # the Hi word alone
    fw.values["wide"] = 1 << 40 | 0xABCD0001  # held wider than the register: the register's words
    assert front.read(0x0014, 2) == (0xABCD, 0x0001)
