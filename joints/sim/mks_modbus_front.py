"""MKS Modbus-RTU front (manual Part 8): the MKS firmware seen through its Part 8 requests.

Rule: a slave of a :class:`~joints.sim.modbus_front.ModbusDeviceBus`, reaching the firmware only by
parameter name through the Part 8 map of the firmware's profile (:func:`~joints.devices.mks.modbus.modbus_map`,
the host driver's too) - the same names as the native front, so both fronts drive the same firmware identically. Only while the drive speaks Modbus
(0x8E on) does it answer.

* FC04 reads exactly the documented blocks (start address and register count of Part 8); another
  address -> exception 02, another count -> 03. FC03 -> exception 01 (Part 8 reads with FC04).
* FC06 writes one setting or command, FC16 one multi-field command with all its fields; the reply
  echoes the request. An unknown address (or one of a later firmware: 0x40, 0x98 before V1.0.9)
  -> 02; a register count or byte count other than the block's -> 03.
* A write the drive cannot carry out - the cases the native protocol answers with status 0: a
  value out of range or refused, a command it cannot execute now (motion while disabled or in a
  pulse work mode, enable in a pulse mode) - is answered by firmware V1.0.6 and later as their
  manuals say ("If write fails, the function code 06H response frame register data is 0xFFFF.
  The function code 10H response frame register quantity is 0"); V1.0.5 documents no failure
  reply: the twin answers exception 03 (value) or 04 (server device failure), our choice.
* The 0x90 home-parameter request is accepted EXACTLY as the manual prints it (3 registers, byte
  count 5, 5 data bytes; ERRATA DOC-MKS-5) and recorded in :attr:`MksModbusFront.quirks`; every
  other request whose counts disagree gets exception 03 - also when it arrives as raw bytes that
  a Modbus codec rejects (:meth:`MksModbusFront.malformed`).
"""

from __future__ import annotations

from typing import Any

from joints.codecs import modbus as mb
from joints.devices.mks.modbus import FC_READ, FC_WRITE_MULTIPLE, FC_WRITE_SINGLE, MksModbusMap, ModbusBlock, modbus_map
from joints.devices.mks.native import OPTIONAL_FIELDS, Command
from joints.devices.quirks import MKS_FAILURE_REPLIES
from joints.errors import CommandError, ParameterRefused
from joints.sim.mks import MksFirmware
from joints.sim.modbus_front import ILLEGAL_DATA_ADDRESS, ILLEGAL_DATA_VALUE, ILLEGAL_FUNCTION, SERVER_DEVICE_FAILURE

__all__ = ["MksModbusFront"]


class _Exception(Exception):
    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


class _Failed(_Exception):
    """The drive could not carry out a write (the native protocol's status 0)."""


#: FC06 register data / FC16 register quantity of a failure reply (V1.0.6+)
FAILED_VALUE = 0xFFFF
FAILED_COUNT = 0


class MksModbusFront:
    """One MKS drive on a Modbus RTU bus (see the module docstring)."""

    def __init__(self, firmware: MksFirmware) -> None:
        self.firmware = firmware
        #: the non-standard frames accepted as documented quirks: (block title, PDU after the function code)
        self.quirks: list[tuple[str, bytes]] = []

    @property
    def address(self) -> int:
        return int(self.firmware.values["slave_address"])

    @property
    def speaks(self) -> bool:
        return bool(self.firmware.values["modbus_rtu"])

    def handle(self, request: Any) -> mb.Reply | None:
        """Execute a request addressed to this slave; the reply (None while the drive speaks the native protocol)."""
        if not self.speaks:
            return None
        self.firmware.frame_received()
        if not self.firmware.hears(getattr(request, "address", -1)):
            return None  # the IAP boot loader or silent state (V1.0.8 0x50): no answer
        try:
            if isinstance(request, mb.ReadInputRegisters):
                return mb.ReadRegistersReply(request.slave, request.function, self._read(request.address, request.count))
            if isinstance(request, mb.WriteSingleRegister):
                try:
                    self._write(self._block(FC_WRITE_SINGLE, request.address), request.value.to_bytes(2, "big"))
                except _Failed:
                    if not self.failure_replies:
                        raise
                    return mb.WriteSingleRegisterReply(request.slave, request.address, FAILED_VALUE)
                return mb.WriteSingleRegisterReply(request.slave, request.address, request.value)
            if isinstance(request, mb.WriteMultipleRegisters):
                n = len(request.values)
                block = self._block(FC_WRITE_MULTIPLE, request.address, n)
                if not block.accepts(n, 2 * n):
                    raise _Exception(ILLEGAL_DATA_VALUE)
                try:
                    self._write(block, b"".join(v.to_bytes(2, "big") for v in request.values))
                except _Failed:
                    if not self.failure_replies:
                        raise
                    return mb.WriteMultipleRegistersReply(request.slave, request.address, FAILED_COUNT)
                return mb.WriteMultipleRegistersReply(request.slave, request.address, n)
            if isinstance(request, mb.UnsupportedRequest) and request.function == FC_WRITE_MULTIPLE:
                return self._raw_write_multiple(request)
            raise _Exception(ILLEGAL_FUNCTION)
        except _Exception as exc:
            return mb.ExceptionReply(request.slave, request.function, exc.code)

    def malformed(self, frame: bytes) -> mb.Reply | None:
        """A CRC-valid frame a Modbus codec rejected (byte count): the 0x90 quirk, or exception 03."""
        if len(frame) < 4 or frame[1] != FC_WRITE_MULTIPLE:
            return None
        return self.handle(mb.UnsupportedRequest(frame[0], frame[1], bytes(frame[2:-2])))

    @property
    def map(self) -> MksModbusMap:
        """The Part 8 map of this firmware's profile (0x3B: one status before V1.0.7, two from it)."""
        return modbus_map(self.firmware.firmware.features)

    @property
    def failure_replies(self) -> bool:
        """Firmware V1.0.6+: failed writes get the manual's failure replies, not exceptions."""
        return MKS_FAILURE_REPLIES in self.firmware.firmware.features

    # -- internals ----------------------------------------------------------------------------------
    def _block(self, function: int, address: int, count: int | None = None) -> ModbusBlock:
        block = self.map.find(function, address)
        if block is None or not all(self.firmware.supports(f.name) for f in block.fields
                                    if f.name not in OPTIONAL_FIELDS):
            raise _Exception(ILLEGAL_DATA_ADDRESS)
        longer = self.map.find(function, address, count) if count is not None else None
        if longer is not None and all(self.firmware.supports(f.name) for f in longer.fields):
            return longer  # a longer form this firmware has (V1.0.7's timed 0xF6)
        return block

    def _read(self, address: int, count: int) -> tuple[int, ...]:
        block = self._block(FC_READ, address)
        if count != block.count:
            raise _Exception(ILLEGAL_DATA_VALUE)
        names = [f.name for f in block.fields]
        values = dict(zip(names, self.firmware.read_many(names)))
        data = bytearray(block.byte_count)
        for f in block.fields:  # saturate to the field like the drive's status values, never wrap
            lo, hi = (-(1 << (8 * f.size - 1)), (1 << (8 * f.size - 1)) - 1) if f.signed else (0, (1 << (8 * f.size)) - 1)
            data[f.offset:f.offset + f.size] = min(max(values[f.name], lo), hi).to_bytes(f.size, "big", signed=f.signed)
        return tuple(int.from_bytes(data[i:i + 2], "big") for i in range(0, len(data), 2))

    def _write(self, block: ModbusBlock, data: bytes) -> None:
        try:
            values = block.decode(data)
            for f in block.fields:
                f.check(values[f.name])
        except CommandError:
            raise _Failed(ILLEGAL_DATA_VALUE) from None
        for name in [n for n in values if not self.firmware.supports(n)]:  # a later firmware's optional field:
            if values.pop(name):  # an older one knows only its 0 (0x83 with bit 15 before V1.0.7: out of range)
                raise _Failed(ILLEGAL_DATA_VALUE)
        try:
            status = self.firmware.execute(block.address, values)
        except ParameterRefused:
            raise _Failed(ILLEGAL_DATA_VALUE) from None
        if status == 0 and block.address != Command.CALIBRATE_ENCODER:
            raise _Failed(SERVER_DEVICE_FAILURE)

    def _raw_write_multiple(self, request: mb.UnsupportedRequest) -> mb.Reply:
        pdu = request.pdu
        if len(pdu) < 5:
            raise _Exception(ILLEGAL_DATA_VALUE)
        address, count, byte_count = int.from_bytes(pdu[0:2], "big"), int.from_bytes(pdu[2:4], "big"), pdu[4]
        block = self._block(FC_WRITE_MULTIPLE, address)
        data = pdu[5:]
        if not block.quirk or not block.accepts(count, byte_count) or len(data) != byte_count:
            raise _Exception(ILLEGAL_DATA_VALUE)
        try:
            self._write(block, data)
        except _Failed:
            if not self.failure_replies:
                raise
            return mb.WriteMultipleRegistersReply(request.slave, address, FAILED_COUNT)
        self.quirks.append((block.title, bytes(pdu)))
        return mb.WriteMultipleRegistersReply(request.slave, address, count)

    def __repr__(self) -> str:
        return f"MksModbusFront({self.firmware!r}, address={self.address})"
