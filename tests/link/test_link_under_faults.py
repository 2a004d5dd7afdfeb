"""The link over a faulty line (joints.transports.faulty): what a caller is told when replies go missing.

A write with no intact answer has an unknown outcome: the drive may have executed it. The link
says so with :class:`~joints.errors.OutcomeUnknown` - whether the reply never came, came corrupt
or came as something else - and never sends a non-idempotent write twice.
"""

from __future__ import annotations

import pytest

from joints.clock import ManualClock
from joints.codecs.crc import append_crc
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.erob.registers import EROB_MODBUS
from joints.errors import ChecksumError, OutcomeUnknown, ReplyTimeout, UnexpectedReply
from joints.link import ModbusLink, RetryPolicy
from joints.sim.firmware import Firmware
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.transports.faulty import Faults, FaultyTransport
from joints.transports.loopback import LoopbackTransport

SLAVE = 2
DROP_ALL = Faults(drop=1.0)
NONE = Faults()


def setup(rx: Faults = NONE, tx: Faults = NONE, *, retries: int = 2,
          seed: int = 0) -> tuple[ModbusLink, FaultyTransport, Firmware, ManualClock]:
    fw = Firmware(EROB_PARAMS)
    bus = ModbusDeviceBus([ModbusFront(fw, EROB_MODBUS, SLAVE)])
    clock = ManualClock(10.0)
    line = FaultyTransport(LoopbackTransport(bus), tx=tx, rx=rx, seed=seed, clock=clock, advance=clock.advance,
                           silence=bus.silence)
    link = ModbusLink(line, policy=RetryPolicy(timeout=0.05, retries=retries), clock=clock)
    return link, line, fw, clock


def test_a_write_whose_reply_the_injector_dropped_is_outcome_unknown_and_not_retried() -> None:
    link, line, fw, clock = setup(rx=DROP_ALL)
    with pytest.raises(OutcomeUnknown) as info:
        link.write_register(SLAVE, 0x00F1, 1, idempotent=False)  # start operating
    assert "outcome is unknown" in str(info.value)
    assert fw.write_log == [("start_operating", 1)]  # the drive did execute it, once
    assert link.transactions == 1 and link.retries_used == 0  # sent once: never re-sent blindly
    assert line.counts["rx.drop"] == 1 and line.units["tx"] == 1
    assert clock.now() == pytest.approx(10.0 + 0.05 + 0.05)  # the timeout, then the late window


def test_an_idempotent_write_whose_replies_are_lost_is_retried_then_outcome_unknown() -> None:
    link, _line, fw, _clock = setup(rx=DROP_ALL, retries=2)
    with pytest.raises(OutcomeUnknown):
        link.write_register(SLAVE, 0x0040, 3, idempotent=True)  # operation mode: position
    assert link.transactions == 3 and fw.write_log == [("operation_mode", 3)] * 3


def test_a_write_whose_reply_came_corrupt_is_outcome_unknown_too() -> None:
    link, line, fw, _clock = setup(rx=Faults(corrupt=1.0, max_flips=1))
    with pytest.raises(OutcomeUnknown) as info:
        link.write_register(SLAVE, 0x00F1, 1, idempotent=False)
    assert isinstance(info.value, ChecksumError)  # still says what went wrong
    assert isinstance(info.value, ReplyTimeout)  # and what it means: no (intact) reply
    assert fw.write_log == [("start_operating", 1)] and link.transactions == 1
    assert line.counts["rx.corrupt"] == 1


def test_a_write_answered_by_something_else_is_outcome_unknown() -> None:
    fw = Firmware(EROB_PARAMS)
    bus = ModbusDeviceBus([ModbusFront(fw, EROB_MODBUS, SLAVE)])

    def other_slave(data: bytes) -> bytes:  # the answer comes back with another slave's address
        answer = bus.receive(data)
        return append_crc(bytes((3,)) + answer[1:-2]) if answer else answer

    link = ModbusLink(LoopbackTransport(other_slave), policy=RetryPolicy(timeout=0.05, retries=2),
                      clock=ManualClock())
    with pytest.raises(OutcomeUnknown) as info:
        link.write_register(SLAVE, 0x00F1, 1, idempotent=False)
    assert isinstance(info.value, UnexpectedReply) and "slave 3" in str(info.value)
    assert fw.write_log == [("start_operating", 1)] and link.transactions == 1


def test_a_read_is_never_outcome_unknown() -> None:
    link, _line, _fw, _clock = setup(rx=Faults(corrupt=1.0, max_flips=1))
    with pytest.raises(ChecksumError) as info:
        link.read_registers(SLAVE, 0x0047, 2)
    assert not isinstance(info.value, OutcomeUnknown)
    assert link.transactions == 3  # reads are retried


def test_under_ten_percent_faults_reads_are_never_stale() -> None:
    link, line, fw, _clock = setup(rx=Faults.rate(0.1, max_delay=0.0125), tx=Faults.rate(0.1, max_delay=0.0125),
                                   seed=7)
    wrong = ok = 0
    for i in range(1500):
        fw.set("profile_speed", i)
        try:
            wrong += link.read_registers(SLAVE, 0x0047, 2) != (0, i)
            ok += 1
        except ReplyTimeout:
            pass
        except ChecksumError:
            pass
    assert wrong == 0
    assert ok > 1000  # most reads got through (retries): the zero above counts real answers
    assert sum(line.counts.values()) > 250  # the line really was faulty
