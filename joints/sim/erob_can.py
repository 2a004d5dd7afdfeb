"""eRob CAN custom-protocol front: the SAME eRob firmware as the Modbus front, reached by CAN index.

Rule: the codec of :mod:`joints.codecs.erob_can` in the device role; the firmware
(:class:`~joints.sim.erob.ErobFirmware`) is reached only by parameter name through the map
:data:`~joints.devices.erob.can.EROB_CAN`. One internal state: a twin reached over Modbus and
over CAN in one run reads and writes the same parameters. :class:`ErobCanBus` is the device side
of one CAN bus: it dispatches requests (0x640 + node) to the fronts by node id (the firmware's
``can_address`` at its last power-on) and owns the in-process medium the host's lockstep bus
joins (:mod:`joints.transports.can_sim`).

Answers, as the manual's examples show (chapter 4, 7.1-7.4, appendix 1):

* a read: the value and 0x3E; a write or command: 0x3E; enable/disable (0x0100) with
  ``acks`` acknowledgements (1 as in the 7.4 tables; the chapter 4 monitor shows 6 for enable
  and 5 for disable);
* error replies with appendix 1's codes: 0x0027 start while the motor is not ready (off, or
  its brake still releasing: the 500 ms of 7.4 step 6), 0x0030 start with an invalid motion
  mode, 0x0032 command without its parameter, 0x0033 command with one it does not take, 0x014A
  brake release on a module without brake, 0x0016 / 0x0015 a write the drive refuses while
  enabled / moving;
* refusals appendix 1 has no code for - an unknown index, a command read, a read-only index
  written, a value outside the parameter's range, module information on firmware older than
  X5061715X (note under 7.5.1) - are answered with 0x80, the manual's failure reply (table 7-4).

Behaviour that is the CAN protocol's own:

* the analog set-point 0x01FE is the target speed in speed mode and the target current in
  torque mode (4.2, 4.3): written while the motor is ready it acts at once; written before
  (7.4.4 writes it before "enable") it is held and acts when the motor becomes ready - "the
  motor turns at the target speed once enabled" (4.2 step 4). Disable or stop drops a held
  set-point;
* there is no clear command (7.5.2): appendix 1 #4 clears an error by disabling, fixing the
  cause and enabling again. The twin drops a latched error at "disable" (the manual does not say
  which of the two steps clears it; clearing at disable lets the host see before it enables
  whether the cause persists - a protection whose cause persists trips again at once);
* a start refused with 0x0027 leaves nothing latched (the reply tells the host);
* module information (0x0232) and versions (0x0001/3, /4) are firmware parameters, set from the
  twin's configured model by :func:`identify` (7.5.3).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import can

from joints.codecs import erob_can as ec
from joints.devices.erob.can import BRAKE, EROB_CAN, ModuleConfig, ModuleInfo, Reach, module_info_supported
from joints.devices.erob.registers import MotionMode, MotionStatus, OperationMode
from joints.errors import CommandError, FrameError, ParameterRefused, Refusal
from joints.transports.can_sim import CanMedium, ClockLike

__all__ = [
    "DEFAULT_FIRMWARE_VERSION",
    "DEFAULT_HARDWARE_VERSION",
    "MOTION_IN_PROGRESS",
    "ErobCanBus",
    "ErobCanFront",
    "identify",
    "identify_twin",
]

#: firmware version a twin reports by default (0x0001/4): module information supported (X5061715X)
DEFAULT_FIRMWARE_VERSION = 150617151
#: hardware version a twin reports by default (0x0001/3; 7.5.3's example)
DEFAULT_HARDWARE_VERSION = 1005
MOTION_IN_PROGRESS = 0x0015
WHILE_ENABLED = 0x0016
START_WHILE_OFF = 0x0027
INVALID_MOTION_MODE = 0x0030
NEEDS_PARAMETER = 0x0032
TAKES_NO_PARAMETER = 0x0033
NO_BRAKE = 0x014A

_MODULE_INDEX = 0x0232
_SPEED, _TORQUE = int(OperationMode.SPEED), int(OperationMode.TORQUE)
_INT32 = 1 << 32
_BRAKE_CODE = {v: k for k, v in BRAKE.items()}
_SIZE_RATIO = re.compile(r"eRob(\d+)H(\d+)")


def identify(firmware: Any, config: ModuleConfig | str, *, serial: int, firmware_version: int = DEFAULT_FIRMWARE_VERSION,
             hardware_version: int = DEFAULT_HARDWARE_VERSION, version: str | int = "MC1A.1A.1A") -> ModuleInfo:
    """Make ``firmware`` report module ``config`` (7.5.3) with these versions; returns what it reports.

    The values become power-on defaults (they survive power cycles, like the drive's own).
    """
    info = ModuleInfo.build(config, serial, version=version, hardware_version=hardware_version,
                            firmware_version=firmware_version)
    values = info.values()
    firmware.defaults.update(values)
    firmware.values.update(values)
    firmware.power_on_values = dict(firmware.values)
    return info


def identify_twin(firmware: Any, model: str, node: int) -> ModuleInfo:
    """What a twin reports by default: node id ``node`` (0x0043) and the module of ``model``.

    ``model`` is a whole model string of 7.5.3 (``eRob70H100I-BM-18EN``), or a size and ratio
    (``eRob80H100``) completed with harmonic reducer, I mounting, brake, multi-turn encoder, CAN
    communication and no torque sensor (``eRob80H100I-BM-18CN``); the serial number's sequence is
    the node id.
    """
    try:
        config = ModuleConfig.from_model(model)
    except CommandError:
        m = _SIZE_RATIO.fullmatch(model)
        size, ratio = (int(m.group(1)), int(m.group(2))) if m else (80, 100)
        config = ModuleConfig(size, "H", ratio, "I", "B", "M", "C", "N")
    firmware.defaults["can_address"] = node
    firmware.values["can_address"] = node
    return identify(firmware, config, serial=node)


class ErobCanFront:
    """One eRob's firmware as a node of the CAN custom protocol (see the module docstring).

    ``node``: a fixed node id; by default the firmware's ``can_address`` at its last power-on
    (a new node id takes effect after save and a power cycle, as on the drive).
    """

    def __init__(self, firmware: Any, node: int | None = None, *, acks: int = 1, disable_acks: int | None = None) -> None:
        if acks < 1:
            raise ValueError(f"acks must be >= 1, got {acks}")
        self.firmware = firmware
        self._node = node
        self.acks = acks  #: 0x3E frames for one enable (chapter 4 monitor: 6)
        self.disable_acks = acks if disable_acks is None else disable_acks  #: for one disable (monitor: 5)
        self.held: int | None = None  #: analog set-point waiting for the motor to be ready
        self.requests = 0
        self._readers: dict[str, Callable[[], list[int]]] = {}  #: parameter -> its prepared firmware read
        #: (index, subindex) -> (parameter, its key, readable by this protocol): the read path's lookups
        self._reads: dict[tuple[int, int | None], tuple[str, Any, bool]] = {}

    @property
    def node(self) -> int:
        if self._node is not None:
            return self._node
        return int(self.firmware.power_on_values["can_address"])

    # -- the protocol ---------------------------------------------------------------------------
    def handle(self, request: ec.Request) -> list[ec.Reply]:
        """The replies to one request addressed to this node."""
        self.requests += 1
        self.firmware.frame_received()
        node = request.node
        try:
            if isinstance(request, ec.Read):
                return [self._read(request)]
            if isinstance(request, ec.Write):
                self._write(request)
                return [ec.Ack(node)]
            return self._command(request)
        except ParameterRefused as exc:
            return [self._refusal(node, exc)]
        except _Refused as exc:
            return [ec.ErrorReply(node, exc.code) if exc.code != ec.READ_FAILED else ec.ReadFailed(node)]

    def _refusal(self, node: int, exc: ParameterRefused) -> ec.Reply:
        if exc.reason is Refusal.STATE:
            fw = self.firmware
            if fw.read("motion_status") != MotionStatus.STOP:
                return ec.ErrorReply(node, MOTION_IN_PROGRESS)
            if fw.enabled:
                return ec.ErrorReply(node, WHILE_ENABLED)
        return ec.ReadFailed(node)

    def _name(self, index: int, subindex: int | None) -> str:
        try:
            return EROB_CAN.at(index, subindex)
        except KeyError:
            raise _Refused(ec.READ_FAILED) from None

    def _fw_read(self, name: str) -> int:
        """``firmware.read(name)`` through a read prepared once per parameter (:meth:`Firmware.reader`; the
        same read, without its checks each time)."""
        read = self._readers.get(name)
        if read is None:
            read = self._readers[name] = self.firmware.reader((name,))
        return read()[0]

    def _read(self, request: ec.Read) -> ec.Reply:
        where = (request.index, request.subindex)
        known = self._reads.get(where)
        if known is None:
            name = self._name(request.index, request.subindex)
            key = EROB_CAN.key(name)
            known = self._reads[where] = (name, key, key.reach is Reach.VALUE and EROB_CAN.access(name).readable)
        name, key, readable = known
        if not readable:
            raise _Refused(ec.READ_FAILED)
        if request.index == _MODULE_INDEX and module_info_supported(self._fw_read("firmware_version")) is False:
            raise _Refused(ec.READ_FAILED)  # firmware older than X5061715X has no index 0x0232
        value = self._fw_read(name) // key.scale
        if value > 0x7FFFFFFF:
            value -= _INT32
        return ec.ValueReply(request.node, value)

    def _write(self, request: ec.Write) -> None:
        name = self._name(request.index, request.subindex)
        key = EROB_CAN.key(name)
        if key.reach is not Reach.VALUE or not EROB_CAN.access(name).writable:
            raise _Refused(ec.READ_FAILED)
        value = EROB_CAN.from_wire(name, request.value)
        fw = self.firmware
        if name == "reset_output_encoder" and value != 1:
            raise _Refused(ec.READ_FAILED)  # 7.5.1: "write 1" resets the load-side encoder
        if name == "analog_quantity_value":
            fw.write(name, value)
            self._setpoint(value)
            return
        fw.write(name, value)
        if name == "operation_mode":
            self.held = None

    def _command(self, request: ec.Command) -> list[ec.Reply]:
        node, index, parameter = request.node, request.index, request.parameter
        takes = ec.COMMANDS[index]
        if takes and parameter is None:
            raise _Refused(NEEDS_PARAMETER)
        if not takes and parameter is not None:
            raise _Refused(TAKES_NO_PARAMETER)
        fw = self.firmware
        name = EROB_CAN.at(index)
        if name == "enable_the_motor":
            assert parameter is not None
            if parameter:
                fw.write(name, parameter)
                return [ec.Ack(node)] * self.acks
            self.held = None
            fw.write(name, 0)
            if fw.fault:
                fw.write("clear_errors", 1)  # no clear command over CAN: appendix 1 #4 - disable, fix, enable
            return [ec.Ack(node)] * self.disable_acks
        if name == "start_operating":
            if not fw.ready():
                raise _Refused(START_WHILE_OFF)
            if fw.values["motion_mode"] not in tuple(MotionMode):
                raise _Refused(INVALID_MOTION_MODE)
            fw.write(name, 1)
        elif name == "stop_operating":
            self.held = None
            fw.write(name, 0)
        elif name == "save_parameters":
            fw.write(name, 2)
        elif name == "release_brake":
            brake = (fw.read("module_configuration") >> 16) & 0xF
            if brake == _BRAKE_CODE["F"]:
                raise _Refused(NO_BRAKE)
            fw.write(name, 0)
        return [ec.Ack(node)]

    # -- the analog set-point ---------------------------------------------------------------
    def _setpoint(self, value: int) -> None:
        fw = self.firmware
        if fw.values["analog_quantity_type"] != 0:
            return  # an external analog source drives the set-point, not the bus
        mode = fw.values["operation_mode"]
        if mode not in (_SPEED, _TORQUE):
            return
        if fw.ready() or not value:
            self.held = None
            fw.write("target_speed" if mode == _SPEED else "target_current", value)
        else:
            self.held = value  # acts when the motor is ready (4.2 step 4)

    def tick(self) -> None:
        """A physics substep passed: a held set-point acts once the motor is ready."""
        held = self.held
        if held is not None and self.firmware.ready():
            self.held = None
            self._setpoint(held)


class _Refused(Exception):
    def __init__(self, code: int) -> None:
        super().__init__(f"error 0x{code:04X}")
        self.code = code


class ErobCanBus:
    """The device side of one eRob CAN custom-protocol bus: fronts by node, and its in-process medium.

    Frames go in through :meth:`on_frame` (the medium's peer call, or a served python-can bus);
    each request to a node with a front is answered, everything else (replies, other protocols,
    malformed frames) is ignored as a drive would.
    """

    def __init__(self, fronts: Iterable[ErobCanFront] = (), *, name: str = "can", bitrate: int = 1_000_000,
                 latency: float = 0.0, ideal: bool = False) -> None:
        self.fronts: list[ErobCanFront] = []
        #: bus timing: node -> its drive's reply turnaround [s] (the world fills it from the profiles)
        self.turnarounds: dict[int, float] = {}
        self.medium = CanMedium(name, bitrate=bitrate, ideal=ideal)
        self.medium.answers_only = True  # the drives answer requests; they never send by themselves
        self.channel = self.medium.channel  #: ``can.Bus(interface="joints-sim", channel=...)`` joins this bus
        self.medium.attach_peer(self, latency=latency, name="twins")
        self.frame_errors = 0
        self._last_tick = 0.0
        #: (identifier, data) -> the request it decodes to (immutable): requests repeat from cycle to cycle
        self._requests: dict[tuple[int, bytes], ec.Read | ec.Write | ec.Command] = {}
        #: the world stepping between this bus's frames (a world offers itself: the one-call exchange needs it)
        self.world: Any = None
        for f in fronts:
            self.add(f)

    def add(self, front: ErobCanFront) -> None:
        if any(f.node == front.node for f in self.fronts):
            raise ValueError(f"two emulated drives at CAN node {front.node}")
        self.fronts.append(front)

    def front(self, node: int) -> ErobCanFront | None:
        for f in self.fronts:
            if f.node == node:
                return f
        return None

    def turnaround(self, frame: can.Message) -> float | None:
        """The reply turnaround [s] of the drive a request frame (0x640 + node) addresses; None: unknown."""
        return self.turnarounds.get(frame.arbitration_id - 0x640)

    def can_exchange(self, host: Any, transport: Any) -> Any:
        """The one-call exchange of this bus's steady requests from the python-can node ``host`` (a lockstep bus on
        this bus's medium) wrapped by the link's ``transport`` (:mod:`joints.sim.can_exchange`), or None."""
        return can_exchange.prepare(self.world, self, host, transport)

    def exchange(self, request: ec.Request) -> list[ec.Reply]:
        """Message-level twin of :meth:`on_frame`: the replies to one request ([] where nobody answers)."""
        front = self.front(request.node)
        return [] if front is None else front.handle(request)

    def on_frame(self, frame: can.Message) -> Sequence[can.Message]:
        if frame.is_extended_id or frame.is_remote_frame or frame.is_error_frame:
            return ()
        key = (frame.arbitration_id, bytes(frame.data))
        request = self._requests.get(key)  # a request seen before: its decoding, kept (the steady case)
        if request is None:
            if ec.decoder_role(frame.arbitration_id) is not ec.Role.DEVICE:
                return ()
            try:
                decoded = ec.decode(frame, ec.Role.DEVICE)
            except FrameError:
                self.frame_errors += 1  # a drive stays silent on a malformed frame
                return ()
            assert isinstance(decoded, (ec.Read, ec.Write, ec.Command))
            request = decoded
            if len(self._requests) >= 256:
                self._requests.clear()
            self._requests[key] = request
        return [ec.encode(r) for r in self.exchange(request)]

    # -- the world's clock (joints.sim.world.TimedDeviceBus) ------------------------------------
    def bind_clock(self, clock: ClockLike) -> None:
        self.medium.bind_clock(clock)

    def next_event(self) -> float:
        """When a tick next has work (:class:`joints.sim.world.Announcing`): the medium's next frame edge; every
        substep while a front holds a set-point (it acts once the motor is ready)."""
        for f in self.fronts:
            if f.held is not None:
                return -math.inf
        return self.medium.next_event()

    def holds(self) -> bool:
        """Whether the world may hold a sleep (``World.hold``: its physics and this bus's ticks run later, at the
        medium's next use or the next one-call exchange): see :func:`joints.sim.can_exchange.holds`."""
        return can_exchange.holds(self)

    def tick(self, t: float) -> None:
        if t < self._last_tick:  # the world was reset: the drives were power-cycled
            for f in self.fronts:
                f.held = None
        self._last_tick = t
        self.medium.tick(t)
        for f in self.fronts:
            if f.held is not None:
                f.tick()


# (imported last: it builds on this module; its check of the stock methods is captured when this module loads)
from joints.sim import can_exchange
