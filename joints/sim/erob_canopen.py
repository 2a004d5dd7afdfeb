"""eRob CANopen front: the SAME eRob firmware as the Modbus and CAN fronts, as a CiA 301/402 node.

Rule: the object dictionary IS the firmware's parameters under their CANopen objects
(:data:`~joints.devices.erob.canopen.EROB_CANOPEN`); the front keeps only what CANopen adds (NMT
state, the CiA 402 power state, PDO timers, latched synchronous RPDOs). The codec
(:mod:`joints.codecs.canopen`) answers SDOs (:class:`~joints.codecs.canopen.SdoServer`) and node
guarding; the CiA 402 state machine of :mod:`joints.devices.cia402` drives the firmware's
enable/disable/fault. :class:`ErobCanopenBus` is the device side of one bus: fronts by node id,
the in-process timed medium (:mod:`joints.transports.can_sim`), and the clock that heartbeats,
event timers, inhibit times and life guarding run on. No wall clock.

What the node does (CiA 301 / 402 where chapter 5 is silent; each is an assumption to confirm on a
real eRob, also listed in the README):

* NMT: boot-up (0x700+node, data 00) after power-on and after NMT reset node / reset
  communication, then PRE-OPERATIONAL. The boot-up follows a reset command by
  :data:`BOOT_TIME_COMMUNICATION` (1 ms, as eRunner's monitor shows it) / :data:`BOOT_TIME_NODE`
  of simulated time, not in the same instant (the node's state changes at the command: frames in
  the meantime are treated as after the boot-up). A master that starts waiting for the boot-up
  only after sending the command (canopen's ``wait_for_bootup``) can miss it, here as on a real
  eRob. Reset communication restores 0x1000-0x1FFF to their
  power-on values; reset node also the application (a firmware power cycle). SDO, SYNC and EMCY
  work in PRE-OPERATIONAL and OPERATIONAL, PDOs only in OPERATIONAL, only NMT and node guarding in
  STOPPED. NMT stop or a reset while the drive is enabled switches it off (brake holds).
* SDO refusals: unknown index 0x06020000, unknown sub-index 0x06090011, read-only 0x06010002,
  length 0x06070010, value out of range 0x06090030/31/32, 0x6060 in OPERATION ENABLED 0x08000022
  (E7; taken with the firmware profile ``mode-change-while-enabled``), a mode not in 0x6502 0x06090030, 0x1005 with bit 30 (SYNC producer: no evidence that an
  eRob produces SYNC) 0x06090030, PDO mapping changed while the PDO is valid 0x06010000,
  an object that cannot be mapped 0x06040041, more than 64 bits 0x06040042.
* CiA 402: OPERATION ENABLED is reported at once; the holding brake releases in the firmware's
  500 ms and set-points written meanwhile act when it has (a PP set-point is acknowledged at once
  and started then); in CSP/CSV/CST statusword bit 12 ("drive follows the target") and in IP bit
  12 ("ip mode active", with controlword bit 4) are set from then. Quick stop (option code 0x605A = 2)
  decelerates within the emergency-stop time, then SWITCH ON DISABLED. A firmware fault is
  FAULT with an EMCY carrying the eRob error code (0x603F) and an error register by CiA 301 class;
  fault reset (rising bit 7) clears it and sends EMCY 0x0000. Halt (bit 8) decelerates with the
  profile deceleration.
* Modes: PP (new set-point bit 4 edge, acknowledge bit 12 while bit 4 is held, change set
  immediately bit 5; with bit 5 = 0 a new set-point waits until the running move ends; relative
  bit 6; target reached bit 10), PV (0x60FF with 0x6083/0x6084; bit 10 at speed, bit 12 speed 0),
  PT (0x6071 per mille of rated torque), CSP (0x607A streamed: the reference moves linearly
  towards each set-point over :meth:`CanopenFront.stream_period` - 0x60C2 where set, else the
  mean SYNC interval over the last 8 SYNCs, else 0x1006, else 1 ms - and stops at it: never past
  the newest set-point, so a SYNC interval other than 0x1006 neither overshoots nor faults), CSV (0x60FF with the profile ramps, as eRunner's CSV
  sets them), CST (0x6071), IP (0x60C1:01 streamed over the 0x60C2 period while bit 4 is set).
* PDOs: synchronous TPDOs (types 1..240) sampled at SYNC, every n-th SYNC; event TPDOs (254/255)
  on change of their data (not faster than the inhibit time) and every event timer; synchronous
  RPDOs latched and applied at the next SYNC, event RPDOs at once; an RPDO is applied whole,
  controlword last; a short RPDO is dropped with EMCY 0x8210.
* Heartbeat producer 0x1017; node guarding replies with the toggle bit; life guarding (guard
  time 0x100C x life time factor 0x100D, from the first guard request) trips EMCY 0x8130 and a
  fault.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import can

from joints.codecs import canopen as co
from joints.devices import cia402
from joints.devices.cia402 import Mode, State
from joints.devices.erob.canopen import (
    EROB_CANOPEN,
    MODE_CHANGE_REFUSED,
    QUICK_STOP_OPTION_CODE,
    SUPPORTED_MODES,
    CanopenObject,
    has_index,
    mode_change_allowed,
    name_at,
    objects,
)
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.erob.registers import AchieveStatus, MotionMode, OperationMode
from joints.devices.erob.state import ENABLE_DELAY
from joints.devices.quirks import EROB_CANOPEN_MODE_CHANGE_WHILE_ENABLED
from joints.errors import CommandError, DeviceRejected, FrameError, ParameterRefused, Refusal, RegisterError
from joints.sim import erob_kernel
from joints.transports.can_sim import CanMedium, ClockLike

__all__ = ["LIFE_GUARD_ERROR", "CanopenFront", "ErobCanopenBus"]

LIFE_GUARD_ERROR = 0x8130  #: EMCY / fault code of a life-guarding timeout (CiA 301)
#: s from an NMT reset command to the node's boot-up: reset communication as eRunner's monitor shows
#: it (figs 5-18, 5-23, 5-27: the boot-up within 1 ms), reset node (not shown) an assumption
BOOT_TIME_COMMUNICATION = 0.001
BOOT_TIME_NODE = 0.05
PDO_LENGTH_ERROR = 0x8210  #: EMCY of an RPDO shorter than its mapping
SYNC_WINDOW = 8  #: SYNCs over which the SYNC interval is measured
_A = co.SdoAbortCode
_POSITION, _SPEED, _TORQUE = int(OperationMode.POSITION), int(OperationMode.SPEED), int(OperationMode.TORQUE)
#: CiA 402 mode -> the firmware's operation mode
_FIRMWARE_MODE = {Mode.PP: _POSITION, Mode.CSP: _POSITION, Mode.IP: _POSITION, Mode.PV: _SPEED, Mode.CSV: _SPEED,
                  Mode.PT: _TORQUE, Mode.CST: _TORQUE}
_COMM = range(0x1000, 0x2000)  #: the communication profile area (reset communication)
_COMM_NAMES = tuple(n for n, o in objects() if o.index in _COMM)
_PDO_AREA = range(0x1400, 0x1C00)
#: 0x6060 value -> its mode (what ``Mode(value)`` gives, without the enum call)
_MODE_OF = {int(m): m for m in Mode}
#: (state, target reached, bit 12, bit 13) -> the statusword :func:`cia402.make_statusword` makes of them: it is a
#: pure function of its arguments (module constants and bit tests only), so each word is made once per process
_STATUSWORDS: dict[tuple[State, bool, bool, bool], int] = {}
#: objects the front computes on read (the others are the firmware's parameters)
_STATUS = frozenset({"statusword", "modes_of_operation_display", "error_register", "error_code",
                     "target_torque", "torque_actual_value"})


def _statusword_of(state: State, reached: bool, bit12: bool, bit13: bool) -> int:
    """The twin's statusword (:func:`cia402.make_statusword`, remote, no warning) of ``state`` and those flags,
    made once per process for each (state, flags): a pure function of them (module constants and bit tests)."""
    key = (state, bool(reached), bool(bit12), bool(bit13))
    word = _STATUSWORDS.get(key)
    if word is None:
        word = _STATUSWORDS[key] = cia402.make_statusword(state, target_reached=reached, bit12=bit12, bit13=bit13,
                                                          warning=False, remote=True)
    return word


@dataclass
class _Pdo:
    """One PDO as configured now (rebuilt when its communication or mapping objects change)."""

    number: int
    cob_id: int
    valid: bool
    transmission_type: int
    inhibit: float  #: s
    event_timer: float  #: s
    entries: tuple[tuple[int, int, int, bool], ...]
    names: tuple[str | None, ...]  #: parameter per entry (None: a dummy / padding entry)
    sync_count: int = 0
    #: per entry: (parameter, lowest, highest value its bits carry); parameter None: a dummy (sent as 0)
    clamps: tuple[tuple[str | None, int, int], ...] = ()
    last_data: bytes | None = None
    last_sent: float = -math.inf
    next_event: float = math.inf
    #: a TPDO's frame as sampled now (:meth:`CanopenFront._frame_maker`), prepared at its first use
    make: Callable[[], can.Message] | None = None
    bits: int = 0  #: the mapped length
    #: an RPDO's data as its mapped values (``co.pdo_unpacker``: the values and errors of ``unpack_pdo``)
    unpack: Callable[[bytes], tuple[int, ...]] | None = None


def _carried(entry: tuple[int, int, int, bool]) -> tuple[int, int]:
    """The lowest and highest value a PDO mapping entry's bits carry."""
    bits, signed = entry[2], entry[3]
    return (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)


def _error_register(code: int) -> int:
    """Error register (0x1001) bits for an EMCY code: generic + the CiA 301 class bit."""
    if not code:
        return 0
    bits = 0x01
    top = code >> 12
    if top == 2:
        bits |= 0x02
    elif top == 3:
        bits |= 0x04
    elif top == 4:
        bits |= 0x08
    elif code & 0xFF00 in (0x8100, 0x8200):
        bits |= 0x10
    elif top not in (0, 5, 6, 7, 8, 9):
        bits |= 0x80
    return bits


class CanopenFront:
    """One eRob's firmware as a CANopen node (see the module docstring).

    ``node``: a fixed node id; by default the firmware's ``can_address`` at its last power-on.
    """

    def __init__(self, firmware: Any, node: int | None = None) -> None:
        self.firmware = firmware
        self._node = node
        self.powered = True
        self.sdo = co.SdoServer(self.node, self._sdo_read, self._sdo_write)
        self.guarding = co.GuardingSlave(self.node)
        self.frames_in = 0
        self.emcy_sent: list[co.Emcy] = []
        self._outbox: list[can.Message] = []
        #: answers due later than at once: (delay after the frame that caused them [s], frame)
        self.later: list[tuple[float, can.Message]] = []
        self._readers: dict[str, Callable[[], list[int]]] = {}  #: parameter -> its prepared firmware read
        self._node_relative()
        self._reset(power_on=True)

    def _node_relative(self) -> None:
        """COB-IDs are their base + the node id from power-on (the CiA 301 pre-defined connection set)."""
        fw, node = self.firmware, self.node
        for name, obj in objects():
            if obj.node_relative:
                value = EROB_PARAMS[name].default + node
                fw.defaults[name] = value
                fw.values[name] = value
                fw.power_on_values[name] = value

    @property
    def node(self) -> int:
        if self._node is not None:
            return self._node
        return int(self.firmware.power_on_values["can_address"])

    # -- power and NMT ------------------------------------------------------------------------
    def _reset(self, *, power_on: bool) -> None:
        self.nmt = co.NmtState.INITIALISING
        self.state = State.SWITCH_ON_DISABLED  # transition 1 (self-test) is done at once
        self.controlword = 0
        self.enabling = False
        self.fault_code = 0
        self.now = float(getattr(self.firmware, "time", 0.0))
        self.sdo.reset()
        self.guarding.reset()
        self.last_guard = -1.0
        self.next_heartbeat = math.inf
        self.latched: dict[int, bytes] = {}  #: RPDO number -> data to apply at the next SYNC
        self.pp_pending: tuple[int, bool] | None = None  #: PP set-point waiting for the running move
        self.pp_active = False
        self.halted = False
        self.stream_from: tuple[float, float] | None = None
        self._pdos: dict[tuple[str, int], _Pdo] | None = None
        #: of the PDOs as configured (built with :attr:`_pdos`): the valid synchronous TPDOs (types 0-240), the
        #: valid event-driven ones (254, 255), the valid RPDOs by COB-ID (the first of each)
        self._sync_tpdos: list[_Pdo] = []
        self._timed_tpdos: list[_Pdo] = []
        self._rpdo_by_cob: dict[int, _Pdo] = {}
        self._pdo_state: dict[tuple[str, int], _Pdo] = {}  #: timers and last data kept over a reconfiguration
        self.controlword_prev = 0
        self.sync_times: list[float] = []  #: drive times of the last SYNCs
        self.sync_interval: float | None = None  #: s between SYNCs, measured (the CSP/IP period)
        self._boot = True  #: the boot-up is due at the next tick

    def power_off(self) -> None:
        """Simulated power loss: the node goes silent and the motor off (the brake holds)."""
        if self.powered:
            fw = self.firmware
            if fw.enabled:
                fw.write("enable_the_motor", 0)
            self.powered = False

    def power_on(self) -> None:
        """Power back: the firmware restarts (saved settings kept) and the node boots."""
        self.firmware.power_cycle()
        self.powered = True
        self._reset(power_on=True)

    def _reset_communication(self) -> None:
        fw = self.firmware
        for name in _COMM_NAMES:
            fw.values[name] = fw.power_on_values.get(name, fw.values[name])
        self._switch_off()
        self.nmt = co.NmtState.INITIALISING
        self.sdo.reset()
        self.guarding.reset()
        self.last_guard = -1.0
        self.latched.clear()
        self._pdos = None
        self._boot = True

    def _switch_off(self) -> None:
        """The drive function stops (NMT stop / reset while enabled): motor off, SWITCH ON DISABLED."""
        fw = self.firmware
        if fw.enabled:
            fw.write("enable_the_motor", 0)
        self.enabling = False
        if self.state not in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            self.state = State.SWITCH_ON_DISABLED

    def _booted(self) -> can.Message:
        self._boot = False
        self.nmt = co.AFTER_BOOT_UP
        period = self.firmware.values["producer_heartbeat_time"] * 1e-3
        self.next_heartbeat = self.now + period if period > 0 else math.inf
        return co.encode(co.BootUp(self.node))

    # -- frames in ----------------------------------------------------------------------------
    def on_frame(self, frame: can.Message, route: co.Route) -> list[can.Message]:
        """The answers to one frame addressed to this node (or to all nodes)."""
        if not self.powered:
            return []
        self.frames_in += 1
        kind = route.kind
        nmt = self.nmt
        if kind is co.Kind.NMT:
            return self._nmt(frame)
        if nmt is co.NmtState.INITIALISING:
            return []
        if kind is co.Kind.GUARD_REQUEST:
            self.last_guard = self.now
            return [self.guarding.reply(nmt)]
        if nmt is co.NmtState.STOPPED:
            return []
        if kind is co.Kind.SDO_RX:
            self.firmware.frame_received()
            reply = self.sdo.feed(frame)
            return [reply] if reply is not None else []
        if kind is co.Kind.SYNC:
            self._sync_seen()
            return self._sync() if nmt is co.NmtState.OPERATIONAL else []
        if kind.is_pdo and nmt is co.NmtState.OPERATIONAL and not frame.is_remote_frame:
            self._rpdo(frame)
        return self._flush()

    def ignores_pdo(self, cob: int) -> bool:
        """Whether :meth:`on_frame` of a PDO frame with COB-ID ``cob`` (in OPERATIONAL) only counts it in
        :attr:`frames_in`: powered, the PDOs configured (:meth:`pdos` built), no valid RPDO with that COB-ID, nothing
        in the outbox and no answer due later - so it changes nothing else and answers nothing."""
        return (self.powered and self._pdos is not None and cob not in self._rpdo_by_cob and not self._outbox
                and not self.later)

    def _flush(self) -> list[can.Message]:
        out, self._outbox = self._outbox, []
        return out

    def _nmt(self, frame: can.Message) -> list[can.Message]:
        try:
            msg = co.decode(frame)
        except FrameError:
            return []
        assert isinstance(msg, co.Nmt)
        if msg.node not in (0, self.node):
            return []
        command = msg.command
        if command is co.NmtCommand.RESET_NODE:
            self.firmware.power_cycle()
            self._reset(power_on=True)
            self.later.append((BOOT_TIME_NODE, self._booted()))
            return []
        if command is co.NmtCommand.RESET_COMMUNICATION:
            self._reset_communication()
            self.later.append((BOOT_TIME_COMMUNICATION, self._booted()))
            return []
        if self.nmt is co.NmtState.INITIALISING:
            return []
        new = co.nmt_transition(self.nmt, command)
        if new is co.NmtState.STOPPED:
            self._switch_off()
        self.nmt = new
        return []

    # -- the object dictionary (SDO) ------------------------------------------------------------
    def _object(self, index: int, subindex: int) -> tuple[str, CanopenObject]:
        try:
            name = name_at(index, subindex)
        except RegisterError:
            code = _A.SUBINDEX_DOES_NOT_EXIST if has_index(index) else _A.OBJECT_DOES_NOT_EXIST
            raise DeviceRejected(f"0x{index:04X}:{subindex:02X}", code=code) from None
        return name, EROB_CANOPEN.key(name)

    def value(self, name: str) -> int:
        """The value of a parameter as CANopen reads it (in the parameter's unit)."""
        fw = self.firmware
        if name not in _STATUS:
            return int(self._read(name))
        if name == "statusword":
            return self.statusword()
        if name == "modes_of_operation_display":
            return int(fw.values["modes_of_operation"])
        if name == "error_code":
            return self.fault_code
        if name == "error_register":
            return _error_register(self.fault_code)
        if name == "target_torque":
            return int(fw.values["target_torque"])
        # torque actual value: per mille of rated torque from the motor current
        torque = self._read("motor_current") * 1e-3 * fw.kt / fw.profile.rated_torque * 1000
        return int(max(-32768, min(32767, round(torque))))

    def _read(self, name: str) -> int:
        """``firmware.read(name)`` through a read prepared once per parameter (:meth:`Firmware.reader`; the
        same read, without its checks each time)."""
        read = self._readers.get(name)
        if read is None:
            read = self._readers[name] = self.firmware.reader((name,))
        return read()[0]

    def _sdo_read(self, index: int, subindex: int) -> bytes:
        name, obj = self._object(index, subindex)
        if not obj.access.readable:
            raise DeviceRejected(name, code=_A.READ_WRITE_ONLY)
        raw = self.value(name)
        if obj.scale != 1.0:
            raw = round(raw / obj.scale)
        lo, hi = (-(1 << (obj.bits - 1)), (1 << (obj.bits - 1)) - 1) if obj.signed else (0, (1 << obj.bits) - 1)
        return max(lo, min(hi, raw)).to_bytes(obj.size, "little", signed=obj.signed)

    def _sdo_write(self, index: int, subindex: int, data: bytes) -> None:
        name, obj = self._object(index, subindex)
        if not obj.access.writable:
            raise DeviceRejected(name, code=_A.WRITE_READ_ONLY)
        if len(data) != obj.size:
            code = _A.LENGTH_TOO_HIGH if len(data) > obj.size else _A.LENGTH_TOO_LOW
            raise DeviceRejected(name, code=code if len(data) else _A.LENGTH_MISMATCH)
        raw = obj.decode(data)
        self.write(name, round(raw * obj.scale) if obj.scale != 1.0 else raw)

    def write(self, name: str, value: int) -> None:
        """Write a parameter as CANopen does (SDO or PDO): the object's checks, then its action."""
        fw = self.firmware
        index = EROB_CANOPEN.key(name).index
        if index in _PDO_AREA:
            self._pdo_write(name, value)
        elif name == "modes_of_operation":
            taken = EROB_CANOPEN_MODE_CHANGE_WHILE_ENABLED in self.firmware.quirks
            if not taken and (not mode_change_allowed(self.state) or self.enabling):
                raise DeviceRejected("0x6060 in OPERATION ENABLED", code=MODE_CHANGE_REFUSED)
            try:
                mode = Mode(value)
            except ValueError:
                raise DeviceRejected("0x6060", code=_A.INVALID_VALUE) from None
            if mode not in SUPPORTED_MODES:
                raise DeviceRejected("0x6060", code=_A.INVALID_VALUE)
            self._store(name, value)
            self._store("operation_mode", _FIRMWARE_MODE[mode])
            self.pp_pending, self.pp_active, self.stream_from = None, False, None
            return
        elif name == "controlword":
            self._store(name, value)
            self._controlword(value)
            return
        elif name == "target_torque":
            self._store(name, value)
            self._apply_target()
            return
        if name == "cob_id_sync" and value & co.SYNC_PRODUCER:
            raise DeviceRejected("0x1005 bit 30: the eRob does not produce SYNC", code=_A.INVALID_VALUE)
        self._store(name, value)
        if name == "producer_heartbeat_time":
            self.next_heartbeat = self.now + value * 1e-3 if value else math.inf
        elif name in ("target_speed", "target_absolute_position", "interpolation_data_record_1"):
            self._apply_target(name)
        elif name == "profile_speed" and value == 0 and self._mode() is Mode.PP and self.state is State.OPERATION_ENABLED:
            fw.write("stop_operating", 0)  # eRunner 5.1 "stop": profile velocity 0 (fig 5-8)

    def _store(self, name: str, value: int) -> None:
        fw = self.firmware
        try:
            if name in ("target_speed", "target_current"):
                fw.set(name, fw.params[name].check(value))  # acts through _apply_target, when the motor is ready
            else:
                fw.write(name, value)
        except ParameterRefused as exc:
            raise DeviceRejected(name, code=self._refusal_code(exc, name, value)) from None
        except CommandError:
            raise DeviceRejected(name, code=_A.INVALID_VALUE) from None

    def _refusal_code(self, exc: ParameterRefused, name: str, value: int) -> int:
        if exc.reason is Refusal.OUT_OF_RANGE:
            p = self.firmware.params[name]
            lo, hi = p.type_range
            lo = lo if p.minimum is None else max(lo, p.minimum)
            hi = hi if p.maximum is None else min(hi, p.maximum)
            return _A.VALUE_TOO_HIGH if value > hi else _A.VALUE_TOO_LOW if value < lo else _A.INVALID_VALUE
        if exc.reason is Refusal.STATE:
            return _A.CANNOT_STORE_DEVICE_STATE
        if exc.reason is Refusal.NOT_WRITABLE:
            return _A.WRITE_READ_ONLY
        return _A.OBJECT_DOES_NOT_EXIST

    # -- PDO configuration --------------------------------------------------------------------
    def _pdo_write(self, name: str, value: int) -> None:
        fw = self.firmware
        kind, rest = name[:4], name[4:]
        number = int(rest[0])
        prefix = f"{kind}{number}"
        valid = not fw.values[f"{prefix}_cob_id"] & co.PDO_INVALID
        if rest[1:].startswith("_mapping_") or rest[1:] == "_mapped_objects":
            if valid:
                raise DeviceRejected(name, code=_A.UNSUPPORTED_ACCESS)  # CiA 301: disable the PDO first
            if rest[1:] == "_mapped_objects":
                self._check_mapping(kind, prefix, value)
            else:
                if fw.values[f"{prefix}_mapped_objects"]:
                    raise DeviceRejected(name, code=_A.UNSUPPORTED_ACCESS)  # sub-index 0 must be 0 first
                self._check_entry(kind, value)
        elif rest[1:] == "_cob_id" and not value & co.PDO_INVALID and valid \
                and (value & 0x7FF) != (fw.values[name] & 0x7FF):
            raise DeviceRejected(name, code=_A.INVALID_VALUE)  # a valid PDO's COB-ID cannot change
        self._store(name, value)
        self._pdos = None

    def _check_entry(self, kind: str, value: int) -> None:
        if not value:
            return
        entry = co.PdoMapEntry.from_value(value)
        if entry.is_dummy:
            if kind == "tpdo" or co.DUMMY_BITS[entry.index] != entry.bits:
                raise DeviceRejected("dummy", code=_A.CANNOT_BE_MAPPED)
            return
        try:
            obj = EROB_CANOPEN.key(name_at(entry.index, entry.subindex))
        except RegisterError:
            raise DeviceRejected("mapping", code=_A.OBJECT_DOES_NOT_EXIST) from None
        ok = obj.pdo_mappable and obj.bits == entry.bits and (obj.access.readable if kind == "tpdo" else obj.access.writable)
        if not ok:
            raise DeviceRejected("mapping", code=_A.CANNOT_BE_MAPPED)

    def _check_mapping(self, kind: str, prefix: str, count: int) -> None:
        fw = self.firmware
        bits = 0
        for i in range(1, count + 1):
            value = fw.values[f"{prefix}_mapping_{i}"]
            if not value:
                raise DeviceRejected("mapping", code=_A.CANNOT_BE_MAPPED)
            self._check_entry(kind, value)
            bits += value & 0xFF
        if bits > co.MAX_PDO_BITS:
            raise DeviceRejected("mapping", code=_A.PDO_LENGTH_EXCEEDED)

    def pdos(self) -> dict[tuple[str, int], _Pdo]:
        """The PDOs as configured now, by ("tpdo"|"rpdo", number)."""
        if self._pdos is None:
            v = self.firmware.values
            out: dict[tuple[str, int], _Pdo] = {}
            for kind in ("rpdo", "tpdo"):
                for n in range(1, 5):
                    p = f"{kind}{n}"
                    cob = v[f"{p}_cob_id"]
                    entries: list[tuple[int, int, int, bool]] = []
                    names: list[str | None] = []
                    for i in range(1, v[f"{p}_mapped_objects"] + 1):
                        e = co.PdoMapEntry.from_value(v[f"{p}_mapping_{i}"])
                        if e.is_dummy:
                            entries.append((e.index, e.subindex, e.bits, False))
                            names.append(None)
                            continue
                        name = name_at(e.index, e.subindex)
                        obj = EROB_CANOPEN.key(name)
                        entries.append(obj.mapping_entry)
                        names.append(name)
                    event = v.get(f"{p}_event_timer", 0) * 1e-3
                    old = self._pdo_state.get((kind, n))
                    pdo = _Pdo(n, cob & 0x7FF, not cob & co.PDO_INVALID, v[f"{p}_transmission_type"],
                               v.get(f"{p}_inhibit_time", 0) * 1e-4, event, tuple(entries), tuple(names))
                    if old is not None:
                        pdo.last_data, pdo.last_sent = old.last_data, old.last_sent
                    pdo.next_event = self.now + event if event > 0 else math.inf
                    pdo.clamps = tuple((name, *_carried(e)) for name, e in zip(pdo.names, pdo.entries))
                    pdo.bits = sum(e[2] for e in pdo.entries)
                    out[(kind, n)] = pdo
            self._pdos = out
            self._pdo_state = out
            tpdos = [pd for (kind, _n), pd in out.items() if kind == "tpdo" and pd.valid]
            self._sync_tpdos = [pd for pd in tpdos if pd.transmission_type <= 240]
            self._timed_tpdos = [pd for pd in tpdos if pd.transmission_type >= 254]
            self._rpdo_by_cob = {}
            for (kind, _n), pd in out.items():
                if kind == "rpdo" and pd.valid:
                    self._rpdo_by_cob.setdefault(pd.cob_id, pd)
        return self._pdos

    def _tpdo_frame(self, pdo: _Pdo) -> can.Message:
        make = pdo.make
        if make is None:
            make = pdo.make = self._frame_maker(pdo)
        return make()

    def _frame_maker(self, pdo: _Pdo) -> Callable[[], can.Message]:
        """A TPDO's frame prepared once: its sample (:meth:`_sampler`) packed by the codec's packer for values
        within their entries' ranges (:func:`joints.codecs.canopen.pdo_packer`: the bytes of ``pack_pdo``)."""
        sample, pack, cob, message = self._sampler(pdo.clamps), co.pdo_packer(pdo.entries), pdo.cob_id, can.Message

        def make() -> can.Message:
            return message(arbitration_id=cob, is_extended_id=False, data=pack(sample()))

        return make

    def _sampler(self, clamps: Sequence[tuple[str | None, int, int]]) -> Callable[[], list[int]]:
        """A prepared sample of a TPDO's mapped values: each as :meth:`value` reads it, clamped to what its bits
        carry, in mapping order; a run of firmware parameters through one prepared read of
        them all (:meth:`Firmware.reader`: the same reads in the same order), a dummy entry 0."""
        plan: list[tuple[Callable[[], Any] | None, bool, tuple[tuple[int, int], ...]]] = []
        block: list[tuple[str, int, int]] = []

        def close() -> None:
            if block:
                plan.append((self.firmware.reader([n for n, _lo, _hi in block]), True,
                             tuple((lo, hi) for _n, lo, hi in block)))
                block.clear()

        for name, lo, hi in clamps:
            if name is not None and name not in _STATUS:
                block.append((name, lo, hi))
                continue
            close()
            if name is None:
                plan.append((None, False, ((lo, hi),)))
            else:  # what value(name) reads, without looking the name up each time
                read = self.statusword if name == "statusword" else functools.partial(self.value, name)
                plan.append((read, False, ((lo, hi),)))
        close()
        steps = tuple(plan)

        def sample() -> list[int]:
            out: list[int] = []
            for read, many, bounds in steps:
                if many:
                    for v, (lo, hi) in zip(read(), bounds):  # type: ignore[misc]
                        v = int(v)
                        if v < lo:
                            v = lo
                        elif v > hi:
                            v = hi
                        out.append(v)
                elif read is None:
                    out.append(0)
                else:
                    v = read()
                    lo, hi = bounds[0]
                    if v < lo:
                        v = lo
                    elif v > hi:
                        v = hi
                    out.append(v)
            return out

        return sample

    def _rpdo(self, frame: can.Message) -> None:
        self.pdos()
        pdo = self._rpdo_by_cob.get(frame.arbitration_id)  # the first valid RPDO with this COB-ID
        if pdo is None:
            return
        data = bytes(frame.data)
        if len(data) * 8 < pdo.bits:
            self._emcy(PDO_LENGTH_ERROR)
            return
        if pdo.transmission_type <= 240:
            self.latched[pdo.number] = data
        else:
            self._apply_rpdo(pdo, data)

    def _apply_rpdo(self, pdo: _Pdo, data: bytes) -> None:
        unpack = pdo.unpack
        if unpack is None:
            unpack = pdo.unpack = co.pdo_unpacker(pdo.entries)
        values = unpack(data)
        control: int | None = None
        for name, value in zip(pdo.names, values):
            if name is None:
                continue
            if name == "controlword":
                control = value
                continue
            try:
                self.write(name, value)
            except DeviceRejected:
                pass  # a PDO gets no answer: a refused value is dropped
        if control is not None:
            self.write("controlword", control)  # the RPDO is applied whole, controlword last

    def _sync(self) -> list[can.Message]:
        out: list[can.Message] = []
        if self._pdos is None:
            self.pdos()
        for pdo in self._sync_tpdos:
            t = pdo.transmission_type
            if 1 <= t <= 240:
                pdo.sync_count += 1
                if pdo.sync_count >= t:
                    pdo.sync_count = 0
                    out.append(self._tpdo_frame(pdo))
            elif t == 0:
                frame = self._tpdo_frame(pdo)
                if bytes(frame.data) != pdo.last_data:
                    pdo.last_data = bytes(frame.data)
                    out.append(frame)
        if self.latched:
            for n in sorted(self.latched):
                self._apply_rpdo(self.pdos()[("rpdo", n)], self.latched.pop(n))
        if self._outbox:
            out += self._flush()
        return out

    # -- CiA 402 ------------------------------------------------------------------------------
    def _mode(self) -> Mode | None:
        value = self.firmware.values["modes_of_operation"]
        mode = _MODE_OF.get(value)
        if mode is None:
            try:
                return Mode(value)
            except ValueError:
                return None
        return mode

    def statusword(self) -> int:
        state = self.state
        mode = self._mode()
        fw = self.firmware
        reached = bit12 = bit13 = False
        if state is State.OPERATION_ENABLED:
            if mode is Mode.PP:
                bit12 = bool(self.controlword & cia402.CW_NEW_SETPOINT) and self.pp_active
                reached = not fw.gen.active and (not self.pp_active or
                                                 self._read("status_of_achieving_position") == AchieveStatus.TARGET_REACHED)
            elif mode in (Mode.PV, Mode.CSV):
                v, target = self._read("current_speed"), fw.values["target_speed"]
                reached = abs(v - target) <= max(100, abs(target) // 100) and abs(fw.v_ref - target) < 1
                bit12 = abs(v) < 100 if mode is Mode.PV else not self.enabling
            elif mode is Mode.IP:
                bit12 = bool(self.controlword & cia402.CW_ENABLE_IP) and not self.enabling  # interpolating
                # at rest at the newest set-point (the reference stops at each set-point until the next)
                reached = not fw.gen.active and abs(fw.v_ref) < 1 and abs(self._read("current_speed")) < 100
            elif mode in (Mode.CSP, Mode.CST):
                bit12 = not self.halted and not self.enabling  # following the target (brake released)
                reached = True
            else:
                reached = True
            if self.halted and abs(fw.v_ref) < 1:
                reached = True
        return _statusword_of(state, reached, bit12, bit13)

    def _controlword(self, cw: int) -> None:
        prev = self.controlword_prev
        self.controlword_prev = cw
        self.controlword = cw
        fw = self.firmware
        state = self.state
        qsoc = QUICK_STOP_OPTION_CODE
        if state is State.FAULT:
            if cia402.command_of(cw, prev) is cia402.Command.FAULT_RESET:
                fw.write("clear_errors", 1)
                if not fw.fault:
                    self.fault_code = 0
                    self.state = State.SWITCH_ON_DISABLED
                    self._emcy(0)
            return
        new = cia402.next_state(state, cw, prev, quick_stop_option_code=qsoc)
        if new is not state:
            self._enter(state, new)
        if self.state is State.OPERATION_ENABLED:
            self._mode_bits(cw, prev)

    def _enter(self, old: State, new: State) -> None:
        fw = self.firmware
        self.state = new
        if new is State.OPERATION_ENABLED:
            if old is not State.QUICK_STOP_ACTIVE:
                fw.write("enable_the_motor", 1)
                self.enabling = True
                self.pp_active, self.pp_pending, self.halted = False, None, False
                self.stream_from = None
        elif old in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE):
            if new is State.QUICK_STOP_ACTIVE:
                fw.write("emergency_stop", 1)
            else:
                self._switch_off()
                self.state = new

    def _mode_bits(self, cw: int, prev: int) -> None:
        fw = self.firmware
        mode = self._mode()
        halt = bool(cw & cia402.CW_HALT)
        if halt and not self.halted:
            self.halted = True
            fw.streaming = False
            if mode in (Mode.PT, Mode.CST):
                fw.set("target_current", 0)
            else:
                fw.write("stop_operating", 0)
            return
        if not halt and self.halted:
            self.halted = False
            if mode in (Mode.PV, Mode.CSV, Mode.PT, Mode.CST):
                self._apply_target()
        if mode is Mode.PP and cw & cia402.CW_NEW_SETPOINT and not prev & cia402.CW_NEW_SETPOINT and not halt:
            target = fw.values["target_absolute_position"]
            immediate = bool(cw & cia402.CW_CHANGE_SET_IMMEDIATELY) or not fw.gen.active
            relative = bool(cw & cia402.CW_RELATIVE)
            if immediate and fw.ready():
                self._pp_start(target, relative)
            else:
                self.pp_pending = (target, relative)
            self.pp_active = True
        if mode is Mode.IP and not cw & cia402.CW_ENABLE_IP:
            fw.streaming = False
            self.stream_from = None
            fw.v_ref = 0.0

    def _pp_start(self, target: int, relative: bool) -> None:
        fw = self.firmware
        fw.set("motion_mode", int(MotionMode.ABSOLUTE))
        if relative:
            fw.set("target_relative_position", 0)
            fw.set("target_absolute_position", round(fw.p_ref) + fw.offset + target)
        else:
            fw.set("target_relative_position", 0)
        fw.write("start_operating", 1)

    def _apply_target(self, name: str | None = None) -> None:
        """A mode's target acts (only in OPERATION ENABLED with the brake released, not halted)."""
        fw = self.firmware
        if self.state is not State.OPERATION_ENABLED or self.enabling or self.halted or not fw.ready():
            return
        mode = self._mode()
        v = fw.values
        if mode in (Mode.PV, Mode.CSV):
            fw.write("target_speed", v["target_speed"])
        elif mode in (Mode.PT, Mode.CST):
            torque = v["target_torque"] * 1e-3 * fw.profile.rated_torque
            current = round(torque / fw.kt * 1000)
            lim = fw.params["target_current"].type_range
            fw.write("target_current", max(lim[0], min(lim[1], current)))
        elif mode is Mode.CSP and name in (None, "target_absolute_position"):
            self._stream(v["target_absolute_position"], self.stream_period())
        elif mode is Mode.IP and name in (None, "interpolation_data_record_1") \
                and self.controlword & cia402.CW_ENABLE_IP:
            self._stream(v["interpolation_data_record_1"], self.stream_period())

    def stream_period(self) -> float:
        """s over which a CSP/IP set-point is approached: 0x60C2 where set (value != 0), else the
        measured SYNC interval, else 0x1006 where set, else 1 ms (see the module docstring)."""
        v = self.firmware.values
        if v["interpolation_time_period_value"]:
            return float(v["interpolation_time_period_value"] * 10.0 ** v["interpolation_time_index"])
        if self.sync_interval is not None:
            return self.sync_interval
        if v["communication_cycle_period"]:
            return float(v["communication_cycle_period"] * 1e-6)
        return 1e-3

    def _sync_seen(self) -> None:
        """The SYNC interval: the mean over the last :data:`SYNC_WINDOW` SYNCs (the drive's clock
        sees a SYNC at the end of a control substep; the mean is free of that quantisation)."""
        t = float(self.firmware.time)
        times = self.sync_times
        if times and t < times[-1]:
            times.clear()  # the world was reset
        times.append(t)
        del times[:-SYNC_WINDOW]
        if len(times) >= 2 and times[-1] - times[0] > 1e-6:
            self.sync_interval = (times[-1] - times[0]) / (len(times) - 1)

    def _stream(self, target: int, period: float) -> None:
        """CSP/IP: the position reference moves from where it is towards ``target`` over ``period``
        and stops there (never past the newest set-point)."""
        fw = self.firmware
        goal = float(fw._clamp_target(target - fw.offset))  # the firmware's own software-limit clamp
        if not fw.streaming:
            fw.streaming = True
            fw.p_ref = fw.pos
        fw.stream_goal = goal
        fw.v_ref = (goal - fw.p_ref) / max(period, 1e-4)

    # -- time ---------------------------------------------------------------------------------
    def tick(self, t: float) -> list[can.Message]:
        """The clock reached ``t``: what the node sends by itself (boot-up, heartbeat, EMCY, event TPDOs)."""
        if t < self.now - 1e-9:  # the world was reset: the drive was power-cycled
            self._reset(power_on=True)
        self.now = t
        if not self.powered:
            return []
        out: list[can.Message] = []
        if self._boot:
            out.append(self._booted())
        fw = self.firmware
        state = self.state
        if self.enabling and fw.ready():
            self.enabling = False
            self._apply_target()
        elif self.enabling and not fw.enabled:
            self.enabling = False
        if fw.fault and state is not State.FAULT:
            self._fault(fw.fault)
        elif state is State.QUICK_STOP_ACTIVE and abs(fw.v_ref) < 1 and not fw.gen.active:
            self.state = cia402.settle(state, quick_stop_option_code=QUICK_STOP_OPTION_CODE)
            if self.state is not State.QUICK_STOP_ACTIVE:
                self._switch_off()
        elif (state is State.OPERATION_ENABLED and self.pp_pending is not None and not fw.gen.active
              and self._mode() is Mode.PP and fw.ready()):
            target, relative = self.pp_pending
            self.pp_pending = None
            self._pp_start(target, relative)
        guard_ms, factor = fw.values["guard_time"], fw.values["life_time_factor"]
        if self.last_guard >= 0 and guard_ms and factor and t - self.last_guard > guard_ms * factor * 1e-3:
            self.last_guard = -1.0
            self._emcy(LIFE_GUARD_ERROR)
            if state in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE) or fw.enabled:
                fw.trip(LIFE_GUARD_ERROR)
                self._fault(LIFE_GUARD_ERROR, emcy=False)
        if t >= self.next_heartbeat and self.nmt is not co.NmtState.INITIALISING:
            period = fw.values["producer_heartbeat_time"] * 1e-3
            self.next_heartbeat = t + period if period > 0 else math.inf
            out.append(co.encode(co.Heartbeat(self.node, self.nmt)))
        if self.nmt is co.NmtState.OPERATIONAL:
            self.pdos()
            if self._timed_tpdos:
                out.extend(self._event_tpdos(t))
        if self._outbox:
            out.extend(self._flush())
        return out

    def next_event(self) -> float:
        """The earliest ``t`` at which :meth:`tick` does more than move :attr:`now`: ``-math.inf`` where the
        kernel's loops decide it (quick stop, a PP set-point waiting for the running move, event-driven TPDOs, a
        fault the front has not reported yet, the motor off while enabling) or frames are due (boot-up, EMCY);
        else the end of the brake's release after an enable, the next heartbeat or life-guarding timeout
        (``math.inf``: none). A fault the loops trip later is not announced: the world stops at it by
        :meth:`fault_watched`."""
        if not self.powered:
            return math.inf
        if self._boot or self._outbox:
            return -math.inf
        e = math.inf
        if self.enabling:  # tick acts once the brake has released (Firmware.ready), or at once if the motor went off
            fw = self.firmware
            if not fw.enabled:
                return -math.inf
            released = fw.enabled_at + ENABLE_DELAY - 1e-9
            e = released - 1e-9 * max(1.0, abs(released))  # a little early: a tick before it acts on nothing
        state = self.state
        if state is State.QUICK_STOP_ACTIVE or (state is not State.FAULT and self.firmware.fault) \
                or (state is State.OPERATION_ENABLED and self.pp_pending is not None):
            return -math.inf
        nmt = self.nmt
        if nmt is co.NmtState.OPERATIONAL and (self._pdos is None or self._timed_tpdos):
            return -math.inf
        if nmt is not co.NmtState.INITIALISING:
            e = min(e, self.next_heartbeat)
        v = self.firmware.values
        guard_ms, factor = v["guard_time"], v["life_time_factor"]
        if self.last_guard >= 0 and guard_ms and factor:
            # tick acts at the first t with t - last_guard > the life time: announced a little early (a tick
            # before it acts on nothing; the next announcement is then the next substep)
            limit = guard_ms * factor * 1e-3
            e = min(e, self.last_guard + limit - 1e-9 * max(1.0, abs(self.last_guard) + limit))
        return e

    def fault_watched(self) -> bool:
        """Whether a fault the drive's loops trip must end a run of substeps at once (:meth:`tick` reports it
        with an EMCY at the end of the substep that tripped it): powered and not in FAULT already."""
        return self.powered and self.state is not State.FAULT

    def _event_tpdos(self, t: float) -> list[can.Message]:
        out: list[can.Message] = []
        self.pdos()
        for pdo in self._timed_tpdos:
            if t - pdo.last_sent < pdo.inhibit - 1e-9:
                continue
            frame = self._tpdo_frame(pdo)
            data = bytes(frame.data)
            if data != pdo.last_data or t >= pdo.next_event - 1e-9:
                pdo.last_data, pdo.last_sent = data, t
                if pdo.event_timer > 0:
                    pdo.next_event = t + pdo.event_timer
                out.append(frame)
        return out

    def _fault(self, code: int, *, emcy: bool = True) -> None:
        self.fault_code = code
        self.enabling = False
        self.state = cia402.settle(cia402.on_fault(self.state))
        if emcy:
            self._emcy(code)

    def _emcy(self, code: int) -> None:
        msg = co.Emcy(self.node, code, _error_register(code))
        self.emcy_sent.append(msg)
        del self.emcy_sent[:-100]
        self._outbox.append(co.encode(msg))


class ErobCanopenBus:
    """The device side of one CANopen bus: fronts by node id, routed by COB-ID, on a timed medium."""

    #: every frame the fronts send is encoded for that sending and never kept (the medium may hand it over)
    fresh_answers = True

    def __init__(self, fronts: Iterable[CanopenFront] = (), *, name: str = "canopen", bitrate: int = 1_000_000,
                 latency: float = 0.0, ideal: bool = False) -> None:
        self.fronts: list[CanopenFront] = []
        #: bus timing: node -> its drive's reply turnaround [s] (the world fills it from the profiles)
        self.turnarounds: dict[int, float] = {}
        self.medium = CanMedium(name, bitrate=bitrate, ideal=ideal)
        self.channel = self.medium.channel
        self._node = self.medium.attach_peer(self, latency=latency, name="twins")
        self.frame_errors = 0
        self._last_tick = 0.0
        self._clock: Any = None
        self._epoch: int | None = None
        self._dt: float | None = None  #: the world's substep (:meth:`bind_substep`); None: ticked every substep
        self._routed: tuple[can.Message, co.Route] | None = None  #: the last frame :meth:`on_frame` classified
        self.pdos_ignored = 0  #: PDOs offered to a front that has not mapped them (:meth:`CanopenFront.ignores_pdo`)
        for f in fronts:
            self.add(f)

    def add(self, front: CanopenFront) -> None:
        if any(f.node == front.node for f in self.fronts):
            raise ValueError(f"two emulated drives at CANopen node {front.node}")
        self.fronts.append(front)

    def front(self, node: int) -> CanopenFront | None:
        for f in self.fronts:
            if f.node == node:
                return f
        return None

    def turnaround(self, frame: can.Message) -> float | None:
        """The answer delay [s] of a frame: a node's turnaround for its SDO requests and guard requests; none for
        SYNC, NMT and PDOs (a CiA 402 drive samples its synchronous TPDOs at the SYNC and sends them then)."""
        routed = self._routed
        route = routed[1] if routed is not None and routed[0] is frame else co.classify(frame)
        if route.kind in (co.Kind.SDO_RX, co.Kind.GUARD_REQUEST):
            return self.turnarounds.get(route.node)
        return 0.0

    def on_frame(self, frame: can.Message) -> Sequence[can.Message]:
        if frame.is_extended_id or frame.is_error_frame:
            self._routed = None
            return ()
        route = co.classify(frame)
        self._routed = (frame, route)  # the medium asks for its turnaround next
        kind = route.kind
        if kind in (co.Kind.NMT, co.Kind.SYNC, co.Kind.TIME):
            out: list[can.Message] = []
            for f in self.fronts:
                out.extend(self._answers(f, frame, route))
            return out
        if kind in (co.Kind.SDO_RX, co.Kind.GUARD_REQUEST):
            front = self.front(route.node)
            return () if front is None else self._answers(front, frame, route)
        if kind.is_pdo:
            out = []
            cob = frame.arbitration_id
            for f in self.fronts:  # PDOs are routed by COB-ID: any front may have mapped it
                if f.nmt is co.NmtState.OPERATIONAL:
                    if f.ignores_pdo(cob):
                        f.frames_in += 1  # all CanopenFront.on_frame would do with it
                        self.pdos_ignored += 1
                        continue
                    out.extend(self._answers(f, frame, route))
            return out
        return ()

    def _answers(self, front: CanopenFront, frame: can.Message, route: co.Route) -> list[can.Message]:
        """The front's answers now; those it gives later (a boot-up) go on the medium at their time."""
        out = front.on_frame(frame, route)
        if front.later:
            now = self.medium.time()
            for delay, answer in front.later:
                self.medium.send_at(self._node, answer, now + delay)
            front.later.clear()
        return out

    # -- the world's clock (joints.sim.world.TimedDeviceBus, Announcing, Watching) -------------
    def bind_clock(self, clock: ClockLike) -> None:
        self.medium.bind_clock(clock)
        self._clock = clock
        self._epoch = getattr(clock, "epoch", None)

    def bind_substep(self, dt: float) -> None:
        """The world's substep [s]: its ticks come at ``k * dt``; from now on the bus announces its next event
        (:meth:`next_event`) and may be ticked only there."""
        self._dt = dt

    def next_event(self) -> float:
        """When a tick next has work (:class:`joints.sim.world.Announcing`): the medium's next frame edge or the
        earliest front's event (:meth:`CanopenFront.next_event`); every substep after a reset (the fronts
        power-cycle at the next tick), or where the bus does not know the world's substep."""
        if self._dt is None or getattr(self._clock, "epoch", None) != self._epoch:
            return -math.inf
        e = self.medium.next_event()
        for f in self.fronts:
            fe = f.next_event()
            e = min(e, fe)
        return e

    def watched(self) -> list[tuple[Any, int]]:
        """Kernel cells (twin, column) whose turning non-zero ends a run of substeps
        (:class:`joints.sim.world.Watching`): the fault code of every drive whose front reports a fault."""
        return [(f.firmware, erob_kernel.FAULT_CODE) for f in self.fronts if f.fault_watched()]

    def tick(self, t: float) -> None:
        """The world finished the substep ending at ``t``. Ticked only at announced events, the bus first
        ticks the substep before ``t`` if it was skipped, as ticking every substep would have: the fronts
        then see the frames the medium delivers at ``t`` with :attr:`CanopenFront.now` at that substep."""
        dt = self._dt
        if dt is not None:
            prev = (round(t / dt) - 1) * dt
            if self._last_tick < prev < t:
                self._tick(prev)
        self._tick(t)

    def _tick(self, t: float) -> None:
        self._last_tick = t
        self._epoch = getattr(self._clock, "epoch", None)
        self.medium.tick(t)
        for f in self.fronts:
            frames = f.tick(t)
            for frame in frames:
                self.medium.send_at(self._node, frame, t)
