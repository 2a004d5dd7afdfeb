"""MKS native RS485 front: the MKS firmware seen through the 0xFA/0xFB/0xFC protocol.

Rule: the same codec as the host, in device role; the firmware is reached only by parameter name
(:class:`~joints.sim.mks.MksFirmware`): a read command reads its fields
(:data:`~joints.devices.mks.native.MKS_NATIVE`), a set or run command executes with all of its
fields. An :class:`MksDeviceBus` dispatches frames by address, as the drives on one RS485 line
do (manual Part 4, 5.2 #13 and #16, 5.7):

* the drive whose slave address matches answers (not while it speaks Modbus, 0x8E on);
* address 0 (broadcast) and a drive's group address (0x8D): every such drive executes, none answers;
* a long packet (0xFC): each drive executes the first command addressed to it, none answers;
* respond off (0x8C): a drive executes its run commands silently, queries still answer;
* timed returns (0x01, V1.0.9): the read's reply every period, unasked, queued like completions;
* completion frames (status 2/3 of run commands and go home with active on; calibrate's 1/2; save/clean's
  2) are queued on the simulated clock and taken with :meth:`MksDeviceBus.take_unsolicited` - the
  in-process transport and ``joints sim serve`` deliver them unasked - or, with their times, with
  :meth:`MksDeviceBus.take_frames` (the timed serial line). The bus lives on the world's clock
  (a :class:`~joints.sim.world.TimedDeviceBus`): what listens with :meth:`MksDeviceBus.on_tick`
  (a timed line) runs after every physics substep. A command that reached the
  drive by broadcast, group or long packet sends no completion either ("slave does not answer").

A value the firmware refuses (unknown, out of range) is answered with status 0, as the drive's
"set fail" / "run fail". Unknown function codes and corrupt frames get no answer - so do the
commands of a later firmware than the twin's (0x40, 0x98 before V1.0.9).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any

from joints.codecs import mks
from joints.devices.mks.native import BLOCK_COMMANDS, MKS_NATIVE, OPTIONAL_FIELDS, REPLY_RULES, Command, fields_of
from joints.devices.params import Access
from joints.devices.quirks import MKS_READ_PARAMETER, MKS_TIMED_RETURNS
from joints.errors import FrameError, ParameterRefused
from joints.sim.mks import MksFirmware

__all__ = ["MksDeviceBus", "MksNativeFront"]

_READS = frozenset(int(c) for c in (
    Command.READ_ENCODER_VALUE_CARRY, Command.READ_ENCODER_VALUE_ADDITION, Command.READ_REAL_TIME_SPEED,
    Command.READ_NUMBER_OF_PULSES, Command.READ_IO_PORTS_STATUS, Command.READ_ERROR_OF_ANGLE,
    Command.READ_EN_PINS_STATUS, Command.READ_GO_BACK_TO_ZERO_STATUS, Command.READ_PROTECTION_STATE,
    Command.QUERY_MOTOR_STATUS, Command.READ_VERSION_INFORMATION, Command.READ_RAW_ENCODER_VALUE))
#: reply fields that are flags or enums on the message
_FLAGS = frozenset(("enabled", "protected"))
_ENUMS: dict[type, Callable[[int], Any]] = {mks.GoBackToZeroStatusReply: mks.GoBackToZeroStatus,
                                            mks.MotorStatusReply: mks.MotorStatus}
_RUN_CODES = frozenset((0xF4, 0xF5, 0xF6, 0xFD, 0xFE))


class MksNativeFront:
    """One MKS drive on a native bus: frames in, firmware calls, reply messages out."""

    def __init__(self, firmware: MksFirmware) -> None:
        self.firmware = firmware
        self.frames = 0  #: frames addressed to this drive (broadcast, group and long packets included)

    @property
    def address(self) -> int:
        return int(self.firmware.values["slave_address"])

    @property
    def group(self) -> int:
        """The group address (0x8D), 0 = none."""
        return int(self.firmware.values["group_address"])

    @property
    def speaks(self) -> bool:
        """The drive speaks the native protocol (0x8E Modbus off)."""
        return not self.firmware.values["modbus_rtu"]

    def handle(self, request: Any, *, answer: bool = True) -> Any:
        """Execute ``request``; the reply message (None when the drive stays silent)."""
        fw = self.firmware
        self.frames += 1
        fw.frame_received()
        if isinstance(request, mks.UnknownRequest) or not fw.hears(request.function):
            return None  # (the IAP boot loader or silent state: V1.0.8 0x50)
        code = request.function
        if isinstance(request, mks.UserId) and request.id is None:  # 0x42 read (V1.0.9); a write goes on below
            return mks.UserIdReply(request.address, fw.values["user_id"]) if fw.supports("user_id") and answer \
                else None
        if code in BLOCK_COMMANDS:
            return self._block(request, answer)
        names = tuple(n for n in fields_of(code) if fw.supports(n) or (code not in _READS and not (
            n in OPTIONAL_FIELDS and getattr(request, MKS_NATIVE.key(n).field) == 0)))  # the older, shorter frame
        if not all(fw.supports(n) for n in names) or (fields_of(code) and not names):
            return None  # a command (or a form of it) of a later firmware: unknown to this one
        if code in _READS:  # (a reply of the older form carries only what this firmware has: 0x3B)
            return self._read_reply(request.address, code, fw.read_many(names)) if answer else None
        given = {n: int(getattr(request, MKS_NATIVE.key(n).field)) for n in names if MKS_NATIVE.key(n).field}
        if not given:
            given = {n: 1 for n in names}  # a command without data: the parameter's "1"
        try:
            status = fw.execute(code, given, answered=answer)
        except ParameterRefused:
            status = 0
        if not answer or (code in _RUN_CODES and not fw.values["slave_respond"]):
            return None
        if code == Command.CALIBRATE_ENCODER:
            return mks.CalibrationReply(request.address, mks.CalibrationStatus(status))
        if code in mks.RUN_REPLY_FUNCTIONS:
            return mks.RunReply(request.address, code, mks.RunStatus(status))
        return mks.SetReply(request.address, code, mks.SetStatus(status))

    @staticmethod
    def _read_reply(address: int, code: int, values: Sequence[int]) -> Any:
        """The reply of read command ``code`` carrying ``values`` (its fields' order)."""
        cls = mks.REPLY_TYPES[code]
        fields: dict[str, Any] = {}
        for n, v in zip(fields_of(code), values):
            f = MKS_NATIVE.key(n).field
            fields[f] = bool(v) if f in _FLAGS else _ENUMS[cls](v) if cls in _ENUMS else v  # (0x3B: both statuses)
        return cls(address, **fields)

    def _parameter(self, address: int, code: int) -> bytes | None:
        """0x00 (V1.0.8): set command ``code``'s data as it would write what the drive holds now (its shorter
        form); None (FF FF) for a command that sets no stored setting (our reading of "parameter-only")."""
        fw = self.firmware
        names = fields_of(code) if code in mks.PARAMETER_CODES and code in mks.REQUEST_TYPES else ()
        kept = [n for n in names if n not in OPTIONAL_FIELDS]
        if not kept or not all(fw.supports(n) and fw.params[n].access is not Access.COMMAND
                               and MKS_NATIVE.key(n).field for n in kept):
            return None
        request = mks.REQUEST_TYPES[code](address, **{MKS_NATIVE.key(n).field: fw.values[n] for n in kept})
        return mks.encode(request)[3:-1]

    def _block(self, request: Any, answer: bool) -> Any:
        """0x46/0x47/0x48 (V1.0.6): all configuration parameters / all statuses at once; 0x01 (V1.0.9):
        a read's timed return; 0x4B (V1.0.8): start the run commands held for it."""
        fw = self.firmware
        if isinstance(request, mks.SyncExecute):
            fw.sync_execute()  # (a firmware without 0x4B ignores it)
            return None  # never answered
        if isinstance(request, mks.ReadParameter):
            if MKS_READ_PARAMETER not in fw.firmware.features or not answer:
                return None  # unknown to this firmware (or not for this drive alone)
            return mks.ParameterReply(request.address, request.code, self._parameter(request.address, request.code))
        if isinstance(request, mks.SetTimedReturn):
            if MKS_TIMED_RETURNS not in fw.firmware.features:
                return None  # unknown to this firmware
            names = fields_of(request.code) if request.code in _READS else ()
            status = fw.set_timed_return(request.code, names, request.times)
            return mks.TimedReturnReply(request.address, request.code, mks.SetStatus(status)) if answer else None
        if not fw.has_blocks:
            return None
        if isinstance(request, mks.WriteAllParameters):
            status = fw.write_all_parameters(request.params)
            return mks.SetReply(request.address, request.function, mks.SetStatus(status)) if answer else None
        if not answer:
            return None
        if isinstance(request, mks.ReadAllParameters):
            return mks.AllParametersReply(request.address, fw.all_parameters())
        return mks.AllStatusReply(request.address, fw.all_status())

    def take_completions(self, now: float) -> list[tuple[float, Any]]:
        """The completion frames due by ``now`` that go on the wire (active on, respond on for run commands),
        with the time each was sent."""
        fw = self.firmware
        out: list[tuple[float, Any]] = []
        for r in fw.take_returns(now):  # 0x01 timed returns: the read's own reply, unasked
            if self.speaks:
                out.append((r.time, self._read_reply(self.address, r.code, r.values)))
        for c in fw.take_completions(now):
            if not c.answered or not self.speaks:
                continue
            rule = REPLY_RULES.get(Command(c.function)) if c.function in _CODES else None
            if rule is not None:
                if rule.silenced_by_respond_off and not fw.values["slave_respond"]:
                    continue
                if rule.completion_needs_active and not fw.values["slave_active"]:
                    continue
            if c.function == Command.CALIBRATE_ENCODER:
                out.append((c.time, mks.CalibrationReply(self.address, mks.CalibrationStatus(c.status))))
            else:
                out.append((c.time, mks.RunReply(self.address, c.function, mks.RunStatus(c.status))))
        out.sort(key=lambda x: x[0])
        return out

    def __repr__(self) -> str:
        return f"MksNativeFront({self.firmware!r}, address={self.address})"


_CODES = frozenset(int(c) for c in Command)


class MksDeviceBus:
    """All emulated MKS drives on one native RS485 bus: bytes in, reply bytes out, completions queued."""

    def __init__(self, fronts: Iterable[MksNativeFront] = (), *,
                 trace: Callable[[str, bytes], None] | None = None) -> None:
        self.fronts: list[MksNativeFront] = []
        for f in fronts:
            self.add(f)
        self._codec = mks.MksCodec(mks.Role.DEVICE)
        self.trace = trace
        self.frame_errors = 0
        self.clock: Any = None
        self._listeners: list[Callable[[float], None]] = []
        #: bus timing: drive address -> its reply turnaround [s] (the world fills it from the profiles)
        self.turnarounds: dict[int, float] = {}

    def add(self, front: MksNativeFront) -> None:
        if any(f.address == front.address for f in self.fronts):
            raise ValueError(f"two emulated MKS drives at address {front.address}")
        self.fronts.append(front)

    # -- the world's clock (joints.sim.world.TimedDeviceBus) -----------------------------------------
    def bind_clock(self, clock: Any) -> None:
        self.clock = clock

    def tick(self, t: float) -> None:
        """The world finished the substep ending at ``t``: whatever listens (a timed line) runs up to it."""
        for listener in self._listeners:
            listener(t)

    def on_tick(self, callback: Callable[[float], None]) -> None:
        """Call ``callback(t)`` after every physics substep."""
        self._listeners.append(callback)

    @property
    def time(self) -> float:
        """The drives' clock (the world's simulated time)."""
        return max((f.firmware.time for f in self.fronts), default=0.0)

    def turnaround(self, frame: bytes) -> float | None:
        """The reply turnaround [s] of the drive a frame (0xFA, address, ...) addresses; None: unknown."""
        if len(frame) < 2:
            return None
        turns = self.turnarounds
        return turns.get(frame[1]) if frame[1] != mks.BROADCAST else max(turns.values(), default=None)

    def receive(self, data: bytes) -> bytes:
        """Feed received bytes; return the bytes the addressed drives send back."""
        codec = self._codec
        if data:  # feeding nothing would undo a flush (silence)
            codec.feed(data)
        out = bytearray()
        while True:
            try:
                msg = codec.next_message()
            except FrameError:
                self.frame_errors += 1  # a drive stays silent on a corrupt frame
                continue
            if msg is None:
                break
            reply = self.exchange(msg)
            if reply is not None:
                out += mks.encode(reply)
        return bytes(out)

    def silence(self) -> bytes:
        """The line went quiet: drop an incomplete frame."""
        self._codec.flush()
        return self.receive(b"")

    def exchange(self, msg: Any) -> Any:
        """Message-level dispatch (see the module docstring); the reply message or None."""
        fronts = [f for f in self.fronts if f.speaks]
        if isinstance(msg, mks.LongPacket):
            for f in fronts:
                cmd = msg.command_for(*((f.address, f.group) if f.group else (f.address,)))
                if cmd is not None:
                    f.handle(cmd, answer=False)
            return None
        address = msg.address
        reply = None
        for f in fronts:
            if address == mks.BROADCAST or (f.group and f.group == address and f.address != address):
                f.handle(msg, answer=False)
            elif f.address == address:
                reply = f.handle(msg)
        return reply

    def take_frames(self, now: float | None = None) -> list[tuple[float, bytes]]:
        """Completion frames the drives sent by ``now`` (default: the drives' time): (time sent, bytes), oldest
        first."""
        t = self.time if now is None else now
        frames = [(at, i, msg) for i, f in enumerate(self.fronts) for at, msg in f.take_completions(t)]
        frames.sort(key=lambda x: (x[0], x[1]))
        return [(at, mks.encode(msg)) for at, _i, msg in frames]

    def take_unsolicited(self) -> bytes:
        """Completion frames the drives sent by now, as bytes (oldest first)."""
        return b"".join(data for _t, data in self.take_frames())
