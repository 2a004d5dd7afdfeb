"""Our Modbus stack against INDEPENDENT Modbus implementations, over real pseudo-terminals.

(a) pymodbus' RTU serial server holds an eRob register image (slave 2, holding registers
    0x0000..0x0100); OUR ``ErobModbusDriver`` -> ``ModbusLink`` -> ``SerialTransport`` talks to it.
    A pty can only be opened by path on its slave side, so two pty pairs are joined by a small
    forwarding thread (a software null-modem cable): pymodbus opens one slave path, we open the
    other.
(b) minimalmodbus as the MASTER against OUR ``ModbusDeviceBus([ModbusFront.plain(EROB_MODBUS, 2)])``,
    served on the master side of one pty by a thread that writes back ``bus.receive(data)``.

Both peers frame, checksum and word-order 32-bit values with their own code, so a mistake shared
by our encoder and our decoder cannot hide here. Every thread, loop and port is shut down by the
fixtures (bounded joins); nothing sleeps on the wall clock.
"""

from __future__ import annotations

import asyncio
import os
import select
import struct
import sys
import threading
from collections.abc import Iterator
from typing import Any

import pytest

from joints.clock import ManualClock
from joints.devices.erob.registers import EROB_MODBUS, STATUS_BLOCK_START, STATUS_BLOCK_WORDS, MotionMode
from joints.drivers.erob_modbus import ErobModbusDriver
from joints.errors import DeviceRejected
from joints.link.modbus import ModbusLink, RetryPolicy
from joints.sim.firmware import Firmware
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="needs POSIX pseudo-terminals")

SLAVE = 2
BAUD = 115200
REPLY_TIMEOUT = 0.5  # seconds: our link's reply timeout and minimalmodbus' port timeout
JOIN_TIMEOUT = 5.0  # bound on every start-up / shutdown wait
IMAGE_WORDS = 0x0101  # holding registers 0x0000..0x0100


def _words32(value: int) -> list[int]:
    """An int32 as two registers, Hi word first, computed with struct (not with our code)."""
    hi, lo = struct.unpack(">HH", struct.pack(">i", value))
    return [hi, lo]


def _open_raw_pty() -> tuple[int, int, str]:
    """(master fd, slave fd, slave path) of a new pty in raw mode (no echo, no line editing)."""
    import tty  # POSIX only: imported here so that collection works on every platform

    master, slave = os.openpty()
    tty.setraw(slave)
    return master, slave, os.ttyname(slave)


class _StoppableThread:
    """A worker thread waiting in select() on its fds plus a self-pipe used to stop it."""

    def __init__(self, name: str) -> None:
        self._stop_r, self._stop_w = os.pipe()
        self.ready = threading.Event()
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._main, name=name, daemon=True)

    def start(self) -> None:
        self._thread.start()
        assert self.ready.wait(JOIN_TIMEOUT), f"{self._thread.name} did not start"

    def _main(self) -> None:
        try:
            self.ready.set()
            self.run()
        except BaseException as exc:  # noqa: BLE001 - reported by stop()
            self.error = exc

    def run(self) -> None:
        raise NotImplementedError

    def stop(self) -> None:
        os.write(self._stop_w, b"x")
        self._thread.join(JOIN_TIMEOUT)
        alive = self._thread.is_alive()
        os.close(self._stop_r)
        os.close(self._stop_w)
        assert not alive, f"{self._thread.name} did not stop"
        if self.error is not None:
            raise self.error


class NullModem(_StoppableThread):
    """Two raw pty pairs whose masters are cross-connected: ``port_a`` <-> ``port_b``."""

    def __init__(self) -> None:
        super().__init__("pty-null-modem")
        self._ma, self._sa, self.port_a = _open_raw_pty()
        self._mb, self._sb, self.port_b = _open_raw_pty()
        self.start()

    def run(self) -> None:
        peer = {self._ma: self._mb, self._mb: self._ma}
        while True:
            readable, _, _ = select.select([self._ma, self._mb, self._stop_r], [], [])
            if self._stop_r in readable:
                return
            for fd in readable:
                try:
                    data = os.read(fd, 4096)
                except OSError:  # the far end is being closed
                    continue
                os.write(peer[fd], data)

    def close(self) -> None:
        try:
            self.stop()
        finally:
            # We kept our own slave fds open all along so the masters never see a hang-up (EIO).
            for fd in (self._ma, self._sa, self._mb, self._sb):
                os.close(fd)


class BusResponder(_StoppableThread):
    """OUR device-side stack on the master side of a pty: bytes in -> ``bus.receive`` -> bytes out."""

    IDLE = 0.01  # seconds of line silence after which an incomplete frame is dropped (t3.5)

    def __init__(self, bus: ModbusDeviceBus) -> None:
        super().__init__("pty-modbus-slave")
        self.bus = bus
        self._master, self._slave, self.port = _open_raw_pty()
        self.start()

    def run(self) -> None:
        while True:
            readable, _, _ = select.select([self._master, self._stop_r], [], [], self.IDLE)
            if self._stop_r in readable:
                return
            if self._master in readable:
                answer = self.bus.receive(os.read(self._master, 4096))
            else:
                answer = self.bus.silence()
            if answer:
                os.write(self._master, answer)

    def close(self) -> None:
        try:
            self.stop()
        finally:
            os.close(self._master)
            os.close(self._slave)


# --------------------------------------------------------------------------------------------
# (a) pymodbus server  <-  our ErobModbusDriver
# --------------------------------------------------------------------------------------------

ACTUAL_POSITION = -123456
PRELOAD = {  # register name -> value, written into pymodbus' image as raw words below
    "error_code": 0,
    "motion_status": 1,
    "status_of_achieving_position": 2,
    "given_position": 400000,
    "actual_position": ACTUAL_POSITION,
    "current_speed": -5000,
    "motor_current": 1500,
    "bus_voltage": 48000,
}
TEMPERATURE = -7  # int16 at 0x0078


def _erob_image() -> list[int]:
    words = [0] * IMAGE_WORDS
    for name, value in PRELOAD.items():
        reg = EROB_MODBUS[name]
        if reg.words == 1:
            words[reg.address] = value
        else:
            words[reg.address : reg.address + 2] = _words32(value)
    words[EROB_MODBUS["part_of_power_temperature"].address] = struct.unpack(">H", struct.pack(">h", TEMPERATURE))[0]
    return words


class PymodbusServer:
    """pymodbus' ModbusSerialServer (RTU framer) on its own asyncio loop in a thread."""

    def __init__(self, port: str) -> None:
        pymodbus_server = pytest.importorskip("pymodbus.server")
        from pymodbus.framer import FramerType
        from pymodbus.simulator import DataType, SimData, SimDevice

        self.pdus: list[tuple[bool, str, int, int, list[int]]] = []  # (sending, class, dev, addr, regs)
        # pymodbus 3.16: SimDevice/SimData replace the deprecated ModbusDeviceContext and
        # ModbusSequentialDataBlock (which now only wrap them). One register block 0x0000..0x0100.
        device = SimDevice(
            id=SLAVE,
            simdata=[SimData(0, values=_erob_image(), datatype=DataType.REGISTERS)],
        )
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self.loop.run_forever, name="pymodbus-server", daemon=True)
        self._thread.start()

        async def start() -> Any:
            server = pymodbus_server.ModbusSerialServer(
                device,
                framer=FramerType.RTU,
                port=port,
                baudrate=BAUD,
                timeout=REPLY_TIMEOUT,
                trace_pdu=self._trace_pdu,
            )
            await server.serve_forever(background=True)  # returns once the port is open
            return server

        try:
            self.server = self._call(start())
        except BaseException:
            self._stop_loop()
            raise

    def _trace_pdu(self, sending: bool, pdu: Any) -> Any:
        self.pdus.append((sending, type(pdu).__name__, pdu.dev_id, pdu.address, list(pdu.registers)))
        return pdu

    def _call(self, coro: Any) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(JOIN_TIMEOUT)

    def holding(self, address: int, count: int) -> list[int]:
        """Read pymodbus' datastore directly (not over the wire)."""
        return list(self._call(self.server.async_getValues(SLAVE, 3, address, count)))

    def received(self, cls: str) -> list[tuple[int, int, list[int]]]:
        """(dev_id, address, registers) of every request of pymodbus class ``cls`` it decoded."""
        return [(d, a, r) for sending, name, d, a, r in self.pdus if not sending and name == cls]

    def _stop_loop(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(JOIN_TIMEOUT)
        alive = self._thread.is_alive()
        if not alive:
            self.loop.close()
        assert not alive, "pymodbus server loop did not stop"

    def close(self) -> None:
        try:
            self._call(self.server.shutdown())
        finally:
            self._stop_loop()


@pytest.fixture
def null_modem() -> Iterator[NullModem]:
    nm = NullModem()
    try:
        yield nm
    finally:
        nm.close()


@pytest.fixture
def pymodbus_server(null_modem: NullModem) -> Iterator[PymodbusServer]:
    server = PymodbusServer(null_modem.port_a)
    try:
        yield server
    finally:
        server.close()


@pytest.fixture
def erob(null_modem: NullModem, pymodbus_server: PymodbusServer) -> Iterator[ErobModbusDriver]:
    pytest.importorskip("serial")
    from joints.transports.serial import SerialTransport

    transport = SerialTransport(null_modem.port_b, BAUD)
    link = ModbusLink(transport, policy=RetryPolicy(timeout=REPLY_TIMEOUT, retries=0))
    # The driver's own clock only paces the manual's 500 ms enable settle: simulated here.
    driver = ErobModbusDriver(link, SLAVE, clock=ManualClock())
    try:
        yield driver
    finally:
        transport.close()


def test_read_int32_hi_word_first(erob: ErobModbusDriver, pymodbus_server: PymodbusServer) -> None:
    assert erob.read("actual_position") == ACTUAL_POSITION
    assert erob.read("part_of_power_temperature") == TEMPERATURE
    assert erob.read("motion_status") == 1
    assert pymodbus_server.received("ReadHoldingRegistersRequest")[0][:2] == (SLAVE, 0x0066)


def test_write_int32_lands_in_pymodbus_datastore(erob: ErobModbusDriver, pymodbus_server: PymodbusServer) -> None:
    erob.write("profile_speed", 10000)
    reg = EROB_MODBUS["profile_speed"]
    assert pymodbus_server.holding(reg.address, 2) == _words32(10000) == [0, 10000]
    # pymodbus decoded our frame as an FC16 of two registers at 0x0047
    assert pymodbus_server.received("WriteMultipleRegistersRequest") == [(SLAVE, 0x0047, [0, 10000])]
    assert erob.read("profile_speed") == 10000

    erob.write("target_absolute_position", 500000)
    assert pymodbus_server.holding(0x0043, 2) == _words32(500000) == [0x0007, 0xA120]
    assert erob.read("target_absolute_position") == 500000

    erob.write("target_relative_position", -2)  # negative: two's complement across both words
    assert pymodbus_server.holding(0x0045, 2) == [0xFFFF, 0xFFFE]


def test_single_register_write_fc06(erob: ErobModbusDriver, pymodbus_server: PymodbusServer) -> None:
    erob.write("operation_mode", 3)
    assert pymodbus_server.holding(0x0040, 1) == [3]
    assert pymodbus_server.received("WriteSingleRegisterRequest") == [(SLAVE, 0x0040, [3])]


def test_state_is_one_block_read(erob: ErobModbusDriver, pymodbus_server: PymodbusServer) -> None:
    state = erob.state()
    reads = pymodbus_server.received("ReadHoldingRegistersRequest")
    assert len(reads) == 1 and reads[0][:2] == (SLAVE, STATUS_BLOCK_START)
    sent = [p for p in pymodbus_server.pdus if p[0] and p[1] == "ReadHoldingRegistersResponse"]
    assert len(sent[0][4]) == STATUS_BLOCK_WORDS == 25
    assert state.position == ACTUAL_POSITION
    assert state.velocity == -5000
    assert state.current == 1500
    assert state.temperature == TEMPERATURE
    assert state.enabled and state.moving
    assert state.fault == 0
    assert state.extra["given_position"] == 400000
    assert state.extra["bus_voltage"] == 48000


def test_move_to_procedure(erob: ErobModbusDriver, pymodbus_server: PymodbusServer) -> None:
    erob.enable()
    erob.move_to(500000, speed=10000, acceleration=20000, deceleration=30000)
    assert pymodbus_server.holding(0x0040, 3) == [3, MotionMode.ABSOLUTE, 0]
    assert pymodbus_server.holding(0x0043, 10) == (
        _words32(500000) + _words32(0) + _words32(10000) + _words32(20000) + _words32(30000)
    )
    assert pymodbus_server.holding(0x00F0, 2) == [1, 1]  # enabled, started
    # the three profile values went out as one FC16
    assert (SLAVE, 0x0047, _words32(10000) + _words32(20000) + _words32(30000)) in pymodbus_server.received(
        "WriteMultipleRegistersRequest"
    )


def test_pymodbus_exception_reply_is_device_rejected(erob: ErobModbusDriver) -> None:
    # 0x0101 is outside pymodbus' block: it answers "illegal data address" (exception 02)
    with pytest.raises(DeviceRejected) as info:
        erob.link.read_registers(SLAVE, 0x0100, 2)
    assert info.value.code == 0x02
    # the link is still in step afterwards
    assert erob.read("actual_position") == ACTUAL_POSITION


# --------------------------------------------------------------------------------------------
# (b) minimalmodbus master  ->  our ModbusDeviceBus / ModbusFront
# --------------------------------------------------------------------------------------------


@pytest.fixture
def our_slave() -> Iterator[tuple[Firmware, BusResponder]]:
    front = ModbusFront.plain(EROB_MODBUS, SLAVE)
    responder = BusResponder(ModbusDeviceBus([front]))
    try:
        yield front.firmware, responder
    finally:
        responder.close()


@pytest.fixture
def instrument(our_slave: tuple[Firmware, BusResponder]) -> Iterator[Any]:
    minimalmodbus = pytest.importorskip("minimalmodbus")
    inst = minimalmodbus.Instrument(our_slave[1].port, SLAVE, mode=minimalmodbus.MODE_RTU)
    inst.serial.baudrate = BAUD
    inst.serial.timeout = REPLY_TIMEOUT
    try:
        yield inst
    finally:
        inst.serial.close()


def test_minimalmodbus_reads_our_int32_and_int16(instrument: Any, our_slave: tuple[Firmware, BusResponder]) -> None:
    import minimalmodbus

    slave, _ = our_slave
    slave.set("actual_position", ACTUAL_POSITION)
    slave.set("part_of_power_temperature", TEMPERATURE)
    slave.set("motion_status", 1)
    # BYTEORDER_BIG = Hi word first, big-endian bytes: the eRob layout
    assert instrument.read_long(0x0066, 3, signed=True, byteorder=minimalmodbus.BYTEORDER_BIG) == ACTUAL_POSITION
    assert instrument.read_register(0x0078, 0, 3, signed=True) == TEMPERATURE
    assert instrument.read_register(0x0061) == 1
    # a block read across the gaps of the status block
    block = instrument.read_registers(STATUS_BLOCK_START, STATUS_BLOCK_WORDS)
    assert block[0x66 - 0x60 : 0x68 - 0x60] == _words32(ACTUAL_POSITION)
    assert block[0x62 - 0x60] == 0  # gap reads 0


def test_minimalmodbus_writes_our_registers(instrument: Any, our_slave: tuple[Firmware, BusResponder]) -> None:
    import minimalmodbus

    slave, _ = our_slave
    instrument.write_long(0x0047, 10000, signed=True, byteorder=minimalmodbus.BYTEORDER_BIG)  # FC16
    assert slave.get("profile_speed") == 10000
    assert ModbusFront(slave, EROB_MODBUS, SLAVE).read(0x47, 2) == (0, 10000)
    instrument.write_long(0x0043, -500000, signed=True, byteorder=minimalmodbus.BYTEORDER_BIG)
    assert slave.get("target_absolute_position") == -500000
    assert instrument.read_long(0x0043, signed=True) == -500000

    instrument.write_register(0x0040, 3, functioncode=6)
    assert slave.get("operation_mode") == 3
    assert instrument.read_register(0x0040) == 3
    assert slave.write_log == [("profile_speed", 10000), ("target_absolute_position", -500000), ("operation_mode", 3)]


def test_minimalmodbus_gets_exception_replies(instrument: Any, our_slave: tuple[Firmware, BusResponder]) -> None:
    import minimalmodbus

    slave, responder = our_slave
    # minimalmodbus waits for the full normal-reply length until its port timeout before it
    # looks at a (shorter) exception reply; keep that wait short.
    instrument.serial.timeout = 0.25
    # 0x0003 lies between modbus_communication_timeout_duration (0x0002) and 0x0030: unknown
    with pytest.raises(minimalmodbus.IllegalRequestError, match="illegal data address"):
        instrument.read_register(0x0003)
    # operation_mode allows 1..3: exception 03 and the image is unchanged
    with pytest.raises(minimalmodbus.IllegalRequestError, match="illegal data value"):
        instrument.write_register(0x0040, 7, functioncode=6)
    assert slave.get("operation_mode") == 0
    assert responder.bus.frame_errors == 0
    # and the slave still answers normally afterwards
    assert instrument.read_register(0x0002) == 0
