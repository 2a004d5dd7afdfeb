"""The MKS SERVO42D/57D Modbus-RTU mode (manual Part 8) as typed data over the same parameters.

Rule: pure data. Part 8 reuses the native function codes as register addresses: FC04 reads the
5.1 quantities (and 0xF1), FC06 writes one-register settings and commands, FC16 sends the
multi-field commands (home, 0_Mode, speed mode, the four position modes). Every entry is named
after the parameter of :data:`~joints.devices.mks.params.MKS_PARAMS` that the native protocol
reaches by the same command, so a driver (and a twin) speaks of ``working_current`` or
``position_mode1_pulses`` whatever the bus protocol.

Why not a :class:`~joints.devices.registers.RegisterTable`
    The MKS "registers" are command codes, not a flat register file: the blocks overlap (FC04
    0x30 reads 3 words 0x30-0x32 while 0x31 and 0x32 are reads of their own; FC16 0x90 spans
    0x90-0x92, which are also FC06 0x91/0x92), values are packed by bytes inside words (dir and
    acc share a word in 0xF6/0xFD), one value is int48 (0x31), and 0x90 sends 5 bytes for 3
    registers. So each request is a :class:`ModbusBlock` (function, start address, register
    count, byte count) of byte :class:`ModbusField` s, and :meth:`MksModbusMap.as_map` gives the
    :class:`~joints.devices.params.ParamMap` the layers above use, like ``RegisterTable.as_map``.

Layouts (Part 8 tables; data bytes after the byte count, big-endian)
    FC04 0x30 (3 regs): carry int32, value uint16. 0x31 (3): int48. 0x32 (1): int16. 0x33 (2):
    int32 pulses (Part 8 prints uint32; read as int32 like 5.1, ERRATA DOC-MKS-4). 0x39 (2):
    int32. 0x34, 0x3A, 0x3B, 0x3E, 0xF1 (1): reserved byte 00, then the uint8 value (0x3B from
    V1.0.7: two statuses, :data:`REVISED`).
    FC06: the value in the register (commands write 1). FC16: 0x90 hmTrig(1) hmDir(1)
    hmSpeed(2) EndLimit(1); 0x9A mode(1) enable(1) speed(1) dir(1); 0xF6 dir(1) acc(1) speed(2);
    0xFD dir(1) acc(1) speed(2) pulses(4); 0xFE/0xF4/0xF5 acc(2) speed(2) position(4).
    Native-only quantities (0x8C respond/active, 0x8D group address; 0x94 "noLimit" homing before
    V1.0.6) have no Modbus entry: :data:`NATIVE_ONLY`.

The 0x90 quirk (ERRATA DOC-MKS-5, manual 8.2 #20, vector mks-modbus-8.2.20-recv)
    The home-parameter request announces 3 registers but a byte count of 5 and carries 5 data
    bytes. A Modbus codec rejects that frame (:class:`~joints.errors.ByteCountError`, the frame in
    its ``data``); :attr:`ModbusBlock.quirk` records it, :meth:`ModbusBlock.accepts` says which
    (count, byte count) a block takes (exactly the documented pair: the twin answers exception 03
    to anything else), and :meth:`ModbusBlock.request_pdu` builds the PDU a driver sends (e.g. as
    ``joints.codecs.modbus.UnsupportedRequest(slave, 16, pdu)``). The reply is an ordinary FC16
    reply for 3 registers (01 10 00 90 00 03 80 25).

V1.0.6-V1.0.9 requests (Modbus-RTU manual V1.0.9; the RS485 manual V1.0.6 Part 8)
    FC16 0x36 write IO port: OUT2_mask, OUT_2, OUT1_mask, OUT_1 (one byte each). FC16 0x9D position
    error protection: byte 0 reserved (0), byte 1 b1 g0Enable (En-triggered zero return, V1.0.6's
    table; V1.0.9 prints only pEnable in b0), b0 pEnable, then Tim and Errs (uint16 each): the two
    flags are bit fields (:attr:`ModbusField.bit`). FC16 0xF6 with a run time (V1.0.7): 4 registers, dir,
    acc, speed, runTime (uint32, 10 ms) - a longer form of 8.3.3 #1 (:attr:`MksModbusMap.variants`,
    :data:`TIMED_SPEED_MODE`).

Requests that changed between firmwares (:data:`REVISED`, one map per profile: :func:`modbus_map`)
    A later manual may read a request's bytes differently: FC04 0x003B is ``00 status`` in V1.0.5
    (Part 8 #8) and V1.0.6 (8.1 #8), ``status1 status2`` in the Modbus-RTU manual V1.0.9 (3.1.7:
    status1 the single-turn zero return, status2 the non-single-turn one, go home), so the low
    byte that was the zero-return status is the homing status from V1.0.7 on. Or it may add a
    request for parameters the native protocol always had: FC16 0x0094, the 'noLimit' homing
    parameters (RS485 V1.0.6 8.2 #22, Modbus-RTU V1.0.9 5.3.3: retValue uint32, hm_mode uint16,
    hm_ma uint16). Each is listed with the firmware feature (:mod:`joints.devices.quirks`) whose
    profiles have it; a profile's map takes it in place of the older block, or adds it. (A request
    of parameters a later firmware added - 0x40, 0x98 ... - is in every map and refused by
    parameter, :data:`~joints.devices.mks.params.FEATURE_OF`.) Driver and twin both take the map
    of the joint's profile, so they cannot disagree on the layout.

Other choices: ``slave_address`` is 1-247 over Modbus (the Modbus address range); microsteps are
written as the count 1-256 (Part 8 shows a 16-bit value, unlike the native byte).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cache
from types import MappingProxyType

from joints.devices.mks.params import MKS_PARAMS
from joints.devices.params import TYPES, Access, ParamMap, ParamSet, check_value, suggest
from joints.devices.quirks import MKS_FIRMWARES, MKS_HOMING_STATUS, MKS_MODBUS_NOLIMIT_HOME, firmware_profile
from joints.errors import CommandError, RegisterError

__all__ = ["FC_READ", "FC_WRITE_MULTIPLE", "FC_WRITE_SINGLE", "MKS_MODBUS", "MKS_MODBUS_OF", "NATIVE_ONLY", "REVISED",
           "TIMED_SPEED_MODE", "MksModbusMap", "ModbusBlock", "ModbusField", "modbus_map"]

FC_READ = 0x04  #: read input registers
FC_WRITE_SINGLE = 0x06  #: write single register
FC_WRITE_MULTIPLE = 0x10  #: write multiple registers


@dataclass(frozen=True, slots=True)
class ModbusField:
    """One parameter inside a Modbus request's data (see the module docstring)."""

    name: str  #: parameter name (MKS_PARAMS)
    function: int  #: 4, 6 or 16
    address: int  #: the block's start register (the native command code)
    offset: int  #: byte offset in the block's data
    size: int  #: bytes on the wire
    type: str  #: value type (a key of joints.devices.params.TYPES)
    access: Access
    minimum: int | None = None  #: narrower bound than the parameter's, over Modbus only
    maximum: int | None = None
    bit: int = -1  #: 0-7: the field is this one bit of the byte at ``offset`` (0x9D's flags); -1: whole bytes
    #: the wire value is the parameter's plus this (0x91 goZeroMode: Modbus 1 / 2 where native has 0 / 1);
    #: a field of size 0 is implied by the request itself (a native command without data: its value is 1)
    bias: int = 0

    @property
    def signed(self) -> bool:
        return self.type.startswith("int")

    def check(self, value: object) -> int:
        return check_value(self.name, self.type, value, self.minimum, self.maximum,
                           where=f" (Modbus FC{self.function:02d} 0x{self.address:04X})")

    def __repr__(self) -> str:
        return f"ModbusField({self.name!r}, FC{self.function:02d} 0x{self.address:04X} +{self.offset}/{self.size})"


@dataclass(frozen=True)
class ModbusBlock:
    """One Part 8 request: function, start register, register count, data bytes and their fields."""

    function: int
    address: int
    count: int  #: registers announced in the request (FC04/FC16) or 1 (FC06)
    byte_count: int  #: data bytes (FC16 byte-count field; 2 x count for FC04/FC06 data)
    title: str  #: the manual's heading
    fields: tuple[ModbusField, ...]
    quirk: str = ""  #: how this request breaks a Modbus rule (an erratum), "" if it does not

    def __post_init__(self) -> None:
        end = 0
        bits: dict[int, set[int]] = {}
        for f in sorted(self.fields, key=lambda f: f.offset):
            if f.bit >= 0:  # flags: distinct bits of one byte (also the free top bit of a value: 0x83)
                if f.size != 1 or f.bit > 7 or f.bit in bits.setdefault(f.offset, set()):
                    raise ValueError(f"{self.title}: bit field {f.name} overlaps or is not one bit of one byte")
                bits[f.offset].add(f.bit)
                continue
            if f.size == 0:
                continue
            if f.offset < end or f.offset + f.size > self.byte_count:
                raise ValueError(f"{self.title}: field {f.name} overlaps or overruns the block")
            if TYPES[f.type][2] > f.size:
                raise ValueError(f"{self.title}: {f.type} does not fit {f.size} bytes ({f.name})")
            end = f.offset + f.size
        if not self.quirk and self.byte_count != 2 * self.count:
            raise ValueError(f"{self.title}: {self.byte_count} bytes for {self.count} registers")

    def accepts(self, count: int, byte_count: int) -> bool:
        """Whether a request announcing ``count`` registers and ``byte_count`` bytes is this block's."""
        return count == self.count and byte_count == self.byte_count

    def decode(self, data: bytes | bytearray) -> dict[str, int]:
        """The block's data bytes -> {parameter name: value}."""
        if len(data) != self.byte_count:
            raise CommandError(f"{self.title}: expected {self.byte_count} data bytes, got {len(data)}")
        plain = bytearray(data)
        for f in self.fields:  # a value field does not see the flag bits inside it
            if f.bit >= 0:
                plain[f.offset] &= ~(1 << f.bit) & 0xFF
        return {f.name: (data[f.offset] >> f.bit) & 1 if f.bit >= 0 else 1 if f.size == 0
                else int.from_bytes(plain[f.offset:f.offset + f.size], "big", signed=f.signed) - f.bias
                for f in self.fields}

    def encode(self, values: Mapping[str, int]) -> bytes:
        """{parameter name: value} (every field of the block) -> the data bytes, range-checked."""
        missing = [f.name for f in self.fields if f.name not in values]
        extra = sorted(set(values) - {f.name for f in self.fields})
        if missing or extra:
            raise CommandError(f"{self.title}: values needed for {', '.join(f.name for f in self.fields)}"
                               + (f"; missing {', '.join(missing)}" if missing else "")
                               + (f"; not in this block: {', '.join(extra)}" if extra else ""))
        out = bytearray(self.byte_count)
        for f in sorted(self.fields, key=lambda f: f.bit):  # values first, then the flags into their bits
            v = f.check(values[f.name])
            if f.bit >= 0:
                if out[f.offset] >> f.bit & 1:
                    raise CommandError(f"{self.title}: a value uses bit {f.bit} of byte {f.offset}, {f.name}'s flag")
                out[f.offset] |= (v & 1) << f.bit
            elif f.size:
                out[f.offset:f.offset + f.size] = (v + f.bias).to_bytes(f.size, "big", signed=f.signed)
        return bytes(out)

    def words(self, values: Mapping[str, int]) -> tuple[int, ...]:
        """The data as 16-bit register values (for FC06/FC16 requests with an even byte count)."""
        if self.byte_count % 2:
            raise CommandError(f"{self.title}: {self.byte_count} data bytes are not whole registers "
                               f"(use request_pdu): {self.quirk}")
        data = self.encode(values)
        return tuple(int.from_bytes(data[i:i + 2], "big") for i in range(0, len(data), 2))

    def decode_words(self, words: Sequence[int]) -> dict[str, int]:
        """Register values (FC04 reply, FC06/FC16 request) -> {parameter name: value}."""
        return self.decode(b"".join((w & 0xFFFF).to_bytes(2, "big") for w in words))

    def request_pdu(self, values: Mapping[str, int]) -> bytes:
        """FC16 PDU after the function code: start, count, byte count, data (quirk blocks included)."""
        if self.function != FC_WRITE_MULTIPLE:
            raise CommandError(f"{self.title}: request_pdu is for FC16 blocks")
        return (self.address.to_bytes(2, "big") + self.count.to_bytes(2, "big") + bytes((self.byte_count,))
                + self.encode(values))


def _f(name: str, function: int, address: int, offset: int, size: int, type_: str, access: Access,
       maximum: int | None = None) -> ModbusField:
    return ModbusField(name, function, address, offset, size, type_, access, maximum=maximum)


R, W, C = Access.R, Access.W, Access.COMMAND


def _read(address: int, count: int, title: str, *fields: tuple[str, int, int, str]) -> ModbusBlock:
    return ModbusBlock(FC_READ, address, count, 2 * count, title,
                       tuple(_f(n, FC_READ, address, o, s, t, R) for n, o, s, t in fields))


def _write(address: int, name: str, type_: str, access: Access, title: str,
           maximum: int | None = None) -> ModbusBlock:
    return ModbusBlock(FC_WRITE_SINGLE, address, 1, 2, title,
                       (_f(name, FC_WRITE_SINGLE, address, 0, 2, type_, access, maximum),))


def _multi(address: int, count: int, byte_count: int, title: str, access: Access,
           *fields: tuple[str, int, int, str], quirk: str = "") -> ModbusBlock:
    return ModbusBlock(FC_WRITE_MULTIPLE, address, count, byte_count, title,
                       tuple(_f(n, FC_WRITE_MULTIPLE, address, o, s, t, access) for n, o, s, t in fields),
                       quirk)


_HOME_QUIRK = ("ERRATA DOC-MKS-5 (manual 8.2 #20): the request announces Quantity of Registers = 3 and "
               "Bytes = 05 and carries 5 data bytes (hmTrig, hmDir, hmSpeed Hi/Lo, EndLimit); Modbus requires "
               "2 x 3 = 6. The drive's own frame is taken as is; the reply is a normal FC16 reply for 3 registers.")

_BLOCKS: tuple[ModbusBlock, ...] = (
    # 8.1 read parameter command (FC04)
    _read(0x30, 3, "8.1 #1 Read the encoder value(carry)",
          ("encoder_carry", 0, 4, "int32"), ("encoder_value", 4, 2, "uint16")),
    _read(0x31, 3, "8.1 #2 Read the encoder value(addition)", ("encoder_addition", 0, 6, "int48")),
    _read(0x32, 1, "8.1 #3 Read the real-time speed of the motor", ("real_time_speed", 0, 2, "int16")),
    _read(0x33, 2, "8.1 #4 Read the number of pulses", ("number_of_pulses", 0, 4, "int32")),
    _read(0x34, 1, "8.1 #5 Read the IO Ports status", ("io_status", 1, 1, "uint8")),
    _read(0x39, 2, "8.1 #6 Read the error of angle", ("angle_error", 0, 4, "int32")),
    _read(0x3A, 1, "8.1 #7 Read the En pins status", ("en_pin_status", 1, 1, "bool")),
    _read(0x3B, 1, "8.1 #8 Read the go back to zero status", ("go_back_to_zero_status", 1, 1, "uint8")),
    _read(0x3E, 1, "8.1 #9 Read the motor shaft protection status", ("protection_state", 1, 1, "bool")),
    _read(0xF1, 1, "8.1 #10 Read the motor status", ("motor_status", 1, 1, "uint8")),
    # 8.2 write parameter command (FC06)
    _write(0x3D, "release_protection", "bool", C, "8.2 #1 Release the motor shaft locked-rotor protection status"),
    _write(0x3F, "restore_default_parameters", "bool", C, "8.2 #2 Restore the default parameter"),
    _write(0x41, "restart_motor", "bool", C, "8.2 #3 Restart the motor"),
    _write(0x80, "calibrate", "bool", C, "8.2 #4 Calibrate the motor"),
    _write(0x82, "work_mode", "uint8", W, "8.2 #5 Set the work mode"),
    ModbusBlock(FC_WRITE_SINGLE, 0x83, 1, 2, "8.2 #6 Set the work current",  # V1.0.9 3.2.3: bit 15 = not saved
                (_f("working_current", FC_WRITE_SINGLE, 0x83, 0, 2, "uint16", W),
                 ModbusField("working_current_unsaved", FC_WRITE_SINGLE, 0x83, 0, 1, "bool", W, bit=7))),
    _write(0x9B, "holding_current", "uint8", W, "8.2 #7 Set the holding current percentage"),
    _write(0x84, "microsteps", "uint16", W, "8.2 #8 Set subdivision"),
    _write(0x85, "en_active_level", "uint8", W, "8.2 #9 Set the active of the En pin"),
    _write(0x86, "motor_direction", "uint8", W, "8.2 #10 Set the direction of motor rotation"),
    _write(0x87, "auto_screen_off", "bool", W, "8.2 #11 Set auto turn off the screen function"),
    _write(0x88, "locked_rotor_protection", "bool", W, "8.2 #12 Set the motor shaft locked-rotor protection"),
    _write(0x89, "subdivision_interpolation", "bool", W, "8.2 #13 Set the subdivision interpolation function"),
    _write(0x8A, "baud_rate", "uint8", W, "8.2 #14 Set the baud rate"),
    _write(0x8B, "slave_address", "uint8", W, "8.2 #15 Set the slave address", maximum=247),
    _write(0x8E, "modbus_rtu", "bool", W, "8.2 #16 Set MODBUS-RTU communication protocol"),
    _write(0x8F, "key_lock", "bool", W, "8.2 #17 Set the key locked or unlocked"),
    _write(0x92, "set_current_axis_to_zero", "bool", C, "8.2 #18 Set Currnet Axis to zero"),
    _write(0xF3, "motor_enable", "bool", W, "8.2 #19 Set serial mode motor enable"),
    _multi(0x90, 3, 5, "8.2 #20 Set the parameter of home", W,
           ("home_trigger_level", 0, 1, "uint8"), ("home_direction", 1, 1, "uint8"),
           ("home_speed", 2, 2, "uint16"), ("end_limit", 4, 1, "bool"), quirk=_HOME_QUIRK),
    _write(0x9E, "limit_port_remap", "bool", W, "8.2 #21 Set limit port remap"),
    _multi(0x9A, 2, 4, "8.2 #22 Set the parameter of 0_Mode", W,
           ("zero_mode", 0, 1, "uint8"), ("zero_mode_set_zero", 1, 1, "bool"),
           ("zero_mode_speed", 2, 1, "uint8"), ("zero_mode_direction", 3, 1, "uint8")),
    # 8.3 motor running command
    _write(0xF7, "emergency_stop", "bool", C, "8.3.1 Emergency stop the motor"),
    ModbusBlock(FC_WRITE_SINGLE, 0x91, 1, 2, "8.3.2 Go home (V1.0.9 5.3.6: goZeroMode 1 origin, 2 coordinate)",
                (_f("go_home", FC_WRITE_SINGLE, 0x91, 0, 0, "bool", C),
                 ModbusField("go_home_mode", FC_WRITE_SINGLE, 0x91, 0, 2, "uint8", C, bias=1))),
    _multi(0xF6, 2, 4, "8.3.3 #1 Run the motor in speed mode", C,
           ("speed_mode_direction", 0, 1, "uint8"), ("speed_mode_acc", 1, 1, "uint8"),
           ("speed_mode_speed", 2, 2, "uint16")),
    _write(0xFF, "save_clean_speed_mode_parameter", "uint8", C, "8.3.3 #3 Save/Clean the parameter in speed mode"),
    _multi(0xFD, 4, 8, "8.3.4 Position model: relative motion by pulses", C,
           ("position_mode1_direction", 0, 1, "uint8"), ("position_mode1_acc", 1, 1, "uint8"),
           ("position_mode1_speed", 2, 2, "uint16"), ("position_mode1_pulses", 4, 4, "uint32")),
    _multi(0xFE, 4, 8, "8.3.5 Position mode2: absolute motion by pulses", C,
           ("position_mode2_acc", 0, 2, "uint8"), ("position_mode2_speed", 2, 2, "uint16"),
           ("position_mode2_abs_pulses", 4, 4, "int32")),
    _multi(0xF4, 4, 8, "8.3.6 Position mode3: relative motion by axis", C,
           ("position_mode3_acc", 0, 2, "uint8"), ("position_mode3_speed", 2, 2, "uint16"),
           ("position_mode3_rel_axis", 4, 4, "int32")),
    _multi(0xF5, 4, 8, "8.3.7 Position mode4: absolute motion by axis", C,
           ("position_mode4_acc", 0, 2, "uint8"), ("position_mode4_speed", 2, 2, "uint16"),
           ("position_mode4_abs_axis", 4, 4, "int32")),
    # Modbus-RTU manual V1.0.9 (the layout of the version word is the native 0x40 reply's, our reading)
    _read(0x40, 2, "V1.0.9 3.1.8 Read version information", ("version_information", 0, 4, "uint32")),
    _multi(0x98, 2, 4, "V1.0.9 3.2.14 Set heartbeat protection time", W,
           ("heartbeat_protection_time", 0, 4, "uint32")),
    _multi(0x36, 2, 4, "V1.0.9 4.2 Write IO port data", C,
           ("write_io_out2_mask", 0, 1, "uint8"), ("write_io_out2", 1, 1, "uint8"),
           ("write_io_out1_mask", 2, 1, "uint8"), ("write_io_out1", 3, 1, "uint8")),
    _write(0x50, "iap_control", "uint8", C, "V1.0.9 3.6 IAP firmware online upgrade"),
    _multi(0x99, 3, 6, "V1.0.9 4.3 Pulse frequency division output", W,
           ("pulse_divider_level", 0, 2, "uint8"), ("pulse_divider_period", 2, 4, "uint32")),
    *(_multi(code, 4, 8, title, W, *((f"{mode}_{k}", 2 * i, 2, "uint16") for i, k in enumerate(("kp", "ki", "kd", "kv"))))
      for code, mode, title in ((0x96, "vfoc", "V1.0.9 3.3.1 Set PID parameters for vFOC mode"),
                                (0x97, "close", "V1.0.9 3.3.2 Set CLOSE mode PID parameters"))),
    ModbusBlock(FC_WRITE_MULTIPLE, 0x9D, 3, 6, "V1.0.9 3.4.2 Set position out-of-tolerance protection parameters",
                (ModbusField("en_trigger_zero_return", FC_WRITE_MULTIPLE, 0x9D, 1, 1, "bool", W, bit=1),
                 ModbusField("position_error_protection", FC_WRITE_MULTIPLE, 0x9D, 1, 1, "bool", W, bit=0),
                 _f("position_error_time", FC_WRITE_MULTIPLE, 0x9D, 2, 2, "uint16", W),
                 _f("position_error_count", FC_WRITE_MULTIPLE, 0x9D, 4, 2, "uint16", W))),
)


@dataclass(frozen=True)
class MksModbusMap:
    """The Part 8 map: blocks by (function, address), fields by parameter name."""

    device: str
    params_all: ParamSet
    blocks: tuple[ModbusBlock, ...]
    #: longer forms of a block (same function and address, more registers, more fields; V1.0.7's timed 0xF6)
    variants: tuple[ModbusBlock, ...] = ()
    _by_name: Mapping[str, ModbusField] = field(init=False, repr=False, compare=False)
    _by_key: Mapping[tuple[int, int], ModbusBlock] = field(init=False, repr=False, compare=False)
    _block_of: Mapping[str, ModbusBlock] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        by_name: dict[str, ModbusField] = {}
        by_key: dict[tuple[int, int], ModbusBlock] = {}
        block_of: dict[str, ModbusBlock] = {}
        for b in self.blocks:
            if (b.function, b.address) in by_key:
                raise ValueError(f"{self.device}: two blocks at FC{b.function:02d} 0x{b.address:04X}")
            by_key[b.function, b.address] = b
            for f in b.fields:
                if f.name in by_name:
                    raise ValueError(f"{self.device}: {f.name!r} in two Modbus blocks")
                if f.name not in self.params_all:
                    raise ValueError(f"{self.device}: Modbus field {f.name!r} is not a parameter")
                by_name[f.name] = f
                block_of[f.name] = b
        for v in self.variants:
            base = by_key.get((v.function, v.address))
            if base is None or base.count == v.count or not {f.name for f in base.fields} < {f.name for f in v.fields}:
                raise ValueError(f"{self.device}: {v.title} is no longer form of a block")
            for f in v.fields:
                if f.name not in by_name:
                    by_name[f.name] = f
                    block_of[f.name] = v
        object.__setattr__(self, "_by_name", MappingProxyType(by_name))
        object.__setattr__(self, "_by_key", MappingProxyType(by_key))
        object.__setattr__(self, "_block_of", MappingProxyType(block_of))

    def __iter__(self) -> Iterator[ModbusField]:
        return iter(self._by_name.values())

    def __len__(self) -> int:
        return len(self._by_name)

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def names(self) -> list[str]:
        return list(self._by_name)

    def get(self, name: str) -> ModbusField:
        f = self._by_name.get(name)
        if f is None:
            if name in self.params_all:
                later = [fw for fw in MKS_FIRMWARES for feature, b in REVISED
                         if feature in firmware_profile("mks", fw).features and name in {x.name for x in b.fields}]
                raise RegisterError(f"{self.device}: {name!r} cannot be reached over Modbus "
                                    + (f"before firmware {later[0]} (the joint's firmware key names an older one; "
                                       "the native protocol reaches it)" if later else "(native protocol only)"))
            raise RegisterError(f"{self.device}: no parameter named {name!r}{suggest(name, self._by_name)}")
        return f

    def block_of(self, name: str) -> ModbusBlock:
        """The request that carries parameter ``name`` (with its sibling fields)."""
        self.get(name)
        return self._block_of[name]

    def block(self, function: int, address: int) -> ModbusBlock:
        b = self._by_key.get((function, address))
        if b is None:
            raise RegisterError(f"{self.device}: no Part 8 request FC{function:02d} at 0x{address:04X}")
        return b

    def find(self, function: int, address: int, count: int | None = None) -> ModbusBlock | None:
        """The block at (function, address); with ``count``, the form announcing that many registers."""
        base = self._by_key.get((function, address))
        if count is None or base is None or base.count == count:
            return base
        return next((v for v in self.variants if (v.function, v.address, v.count) == (function, address, count)),
                    None)

    def base_of(self, block: ModbusBlock) -> ModbusBlock:
        """The short form of a block (itself if it has no other)."""
        return self._by_key[block.function, block.address]

    @property
    def params(self) -> ParamSet:
        """The parameters reachable over Modbus (a subset of MKS_PARAMS, same names)."""
        return ParamSet(self.device, (p for p in self.params_all if p.name in self._by_name))

    def as_map(self, params: ParamSet | None = None) -> ParamMap[ModbusField]:
        """This table as the Modbus RTU map of ``params`` (default: all MKS parameters)."""
        return ParamMap("modbus-rtu", params or self.params_all, dict(self._by_name))


#: V1.0.7's 0xF6 with a run time (Modbus V1.0.9 8.1: 4 registers, dir acc speed runTime)
TIMED_SPEED_MODE = _multi(0xF6, 4, 8, "V1.0.9 8.1 Run the motor in speed mode with a run time", C,
                          ("speed_mode_direction", 0, 1, "uint8"), ("speed_mode_acc", 1, 1, "uint8"),
                          ("speed_mode_speed", 2, 2, "uint16"), ("speed_mode_run_time", 4, 4, "uint32"))

#: requests a later firmware reads in another layout, or adds: (the feature whose profiles have it, the request)
REVISED: tuple[tuple[str, ModbusBlock], ...] = (
    # Modbus-RTU manual V1.0.9 3.1.7 "01H 04H 02H status1 status2" (V1.0.7's homing status); before: "00H status"
    (MKS_HOMING_STATUS, _read(0x3B, 1, "V1.0.9 3.1.7 Read the go back to zero status",
                              ("go_back_to_zero_status", 0, 1, "uint8"), ("homing_status", 1, 1, "uint8"))),
    # RS485 manual V1.0.6 8.2 #22, Modbus-RTU manual V1.0.9 5.3.3 (reply 01 10 00 94 00 04 80 26); not in V1.0.5
    (MKS_MODBUS_NOLIMIT_HOME, _multi(0x94, 4, 8, "V1.0.9 5.3.3 Set the zero-return torque and origin offset", W,
                                     ("home_reverse_angle", 0, 4, "uint32"), ("home_mode", 4, 2, "uint8"),
                                     ("home_current", 6, 2, "uint16"))),
)


@cache
def modbus_map(features: frozenset[str]) -> MksModbusMap:
    """The Part 8 map of a firmware with ``features`` (a profile's :attr:`FirmwareProfile.features`): the
    base blocks, each revised or added one of :data:`REVISED` whose feature it has (the last listed wins)."""
    blocks = {(b.function, b.address): b for b in _BLOCKS}
    for feature, block in REVISED:
        if feature in features:
            blocks[block.function, block.address] = block
    return MksModbusMap("mks-servo42d57d", MKS_PARAMS, tuple(blocks.values()), (TIMED_SPEED_MODE,))


#: the map of each firmware profile (joints.devices.quirks.MKS_FIRMWARES)
MKS_MODBUS_OF: Mapping[str, MksModbusMap] = MappingProxyType(
    {fw: modbus_map(firmware_profile("mks", fw).features) for fw in MKS_FIRMWARES})

#: the map of the newest profile (the default firmware); a driver or twin takes its profile's (:func:`modbus_map`)
MKS_MODBUS = MKS_MODBUS_OF[MKS_FIRMWARES[-1]]

#: parameters only the native protocol reaches (on every firmware)
NATIVE_ONLY: frozenset[str] = frozenset(p.name for p in MKS_PARAMS if not any(p.name in m for m in MKS_MODBUS_OF.values()))
