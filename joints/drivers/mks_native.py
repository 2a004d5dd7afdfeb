"""MKS SERVO42D/57D over the native RS485 protocol: command codes as the parameter access, completion frames.

Rule: the procedures are :class:`~joints.drivers.mks.MksDriver`'s, by parameter name; this module
adds what only the native protocol has:

* :class:`MksNativeAccess` - each parameter is a field of one command (:data:`MKS_NATIVE`): a read
  is that command's query (one per command, several fields from one reply); a write sends the whole
  command with its other fields from the image of what was written before. Reads of write-only
  settings are one 0x47 (read all parameters) from firmware V1.0.6, refused before (the drive
  cannot report them).
* Completion frames (0x8C active = 1): the driver subscribes to its drive's frames, so it knows that
  a move ended without polling (:attr:`MksNativeDriver.completion`); :meth:`MksNativeDriver.wait_motion`
  waits for that frame and, when it does not come (lost to a collision on the half-duplex line),
  finds the end by a status read.
* Respond and active (0x8C), group addresses (0x8D): the link is told after the drive confirmed
  them, so it waits for nothing the drive will not send. Broadcast and long packets go out through
  :meth:`MksNativeDriver.broadcast` / :func:`long_packet` without waiting; the drivers whose drives
  they start note the motion (leaving the rig stops them).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from functools import partial
from typing import Any

from joints.clock import Clock
from joints.codecs import mks
from joints.devices.mks import blocks
from joints.devices.mks import state as st
from joints.devices.mks.native import MKS_NATIVE, OPTIONAL_FIELDS, fields_of
from joints.devices.mks.params import model_params
from joints.devices.mks.profile import MksProfile
from joints.devices.params import ParamSet
from joints.devices.quirks import MKS_ALL_PARAMETERS, MKS_READ_PARAMETER, MKS_TIMED_RETURNS, FirmwareProfile
from joints.drivers.mks import RUN_GROUPS, MksAccess, MksDriver, MksHeartbeat
from joints.errors import CommandError, ConfirmationRequired, MotionTimeout, RegisterError
from joints.link.base import Subscription
from joints.link.mks import MksLink

__all__ = ["MksNativeAccess", "MksNativeDriver", "MksNativeHeartbeatDriver", "long_packet"]

#: the write-only settings 0x47 reports (V1.0.6+)
_HELD = frozenset(n for n, _o, _s in blocks.ALL_PARAMETERS) - blocks.NOT_READ_BACK


class MksNativeAccess(MksAccess):
    """One drive's parameters as native MKS commands (see the module docstring)."""

    protocol = "mks-serial"

    def __init__(self, link: MksLink, address: int, params: ParamSet) -> None:
        super().__init__(params)
        self.link = link
        self.address = address
        self.last_reply: Any = None  #: the reply to the last write (a status message), None if there was none

    def resolve(self, key: str | int) -> str:
        if isinstance(key, int):
            names = fields_of(key)
            if len(names) != 1:
                raise RegisterError(f"{self.params.device}: command 0x{key:02X} " + (
                    f"carries {', '.join(names)}: name the parameter" if names else "is not a parameter command"))
            return names[0]
        MKS_NATIVE.key(key)
        return key

    def where(self, name: str) -> str:
        k = MKS_NATIVE.key(name)
        return f"0x{int(k.command):02X}" + (f" {k.field}" if k.field else "")

    # -- reads ------------------------------------------------------------------------------
    def _query(self, command: int) -> Any:
        return self.link.request(mks.REQUEST_TYPES[command](self.address), idempotent=True)

    def read_version(self, *, retry: bool = True) -> int:
        """0x40 (V1.0.9) version word; ``retry=False``: one attempt (a probe of a drive that may not answer)."""
        reply = self.link.request(mks.ReadVersion(self.address), idempotent=retry)
        if not isinstance(reply, mks.VersionReply):
            raise CommandError(f"{self.params.device}@{self.address}: no version reply")
        return int(reply.version)

    def read_many(self, names: Sequence[str]) -> dict[str, int]:
        """One query per command (0x30 gives carry and value together)."""
        self.require(names)
        out: dict[str, int] = {}
        by_command: dict[int, list[str]] = {}
        held = [n for n in names if not self.params[n].access.readable]
        if held:
            if MKS_ALL_PARAMETERS not in self.features or any(n not in _HELD for n in held):
                n = next(n for n in held if MKS_ALL_PARAMETERS not in self.features or n not in _HELD)
                raise RegisterError(f"{self.params.device}: {n} ({self.where(n)}) cannot be read: the drive does not "
                                    "report it" + ("" if n in _HELD else " (not even in 0x47)")
                                    + ("" if MKS_ALL_PARAMETERS in self.features else
                                       " before firmware v1.0.6 (0x47 read all parameters)"))
            out.update({n: self.read_all()[n] for n in held})
        for n in names:
            if n in out:
                continue
            by_command.setdefault(int(MKS_NATIVE.key(n).command), []).append(n)
        for command, wanted in by_command.items():
            reply = self._query(command)
            if reply is None:
                raise CommandError(f"{self.params.device}@{self.address}: no reply to a read (broadcast/group address?)")
            for n in wanted:
                out[n] = int(getattr(reply, MKS_NATIVE.key(n).field))
        return out

    def read_all(self) -> dict[str, int]:
        """0x47 (V1.0.6): every configuration setting the drive holds, by name; they fill the image."""
        reply = self.link.request(mks.ReadAllParameters(self.address), idempotent=True)
        if not isinstance(reply, mks.AllParametersReply):
            raise CommandError(f"{self.params.device}@{self.address}: no reply to 0x47")
        values = blocks.unpack(blocks.ALL_PARAMETERS, reply.params, skip=blocks.NOT_READ_BACK)
        self.remember(values)
        return values

    # -- writes -----------------------------------------------------------------------------
    def message(self, values: Mapping[str, int], address: int | None = None) -> tuple[Any, dict[str, int]]:
        """The request that writes ``values`` (all parameters of ONE command; the others from the image)."""
        commands = {int(MKS_NATIVE.key(n).command) for n in values}
        if len(commands) != 1:
            raise CommandError(f"{self.params.device}: {sorted(values)} belong to {len(commands)} commands, not one")
        command = commands.pop()
        for n in values:
            if not self.params[n].access.writable:
                raise RegisterError(f"{self.params.device}: {n} is read-only")
        full = self.merged(fields_of(command), values)
        kwargs = {MKS_NATIVE.key(n).field: v for n, v in full.items() if MKS_NATIVE.key(n).field}
        return mks.REQUEST_TYPES[command](self.address if address is None else address, **kwargs), full

    def write_many(self, values: Mapping[str, int], *, idempotent: bool = True) -> None:
        """One frame per command; every field of it sent (the others from the image); all checked first."""
        self.require(values)
        groups: dict[int, dict[str, int]] = {}
        for n, v in values.items():
            groups.setdefault(int(MKS_NATIVE.key(n).command), {})[n] = v
        planned = [self.message(g) for g in groups.values()]  # every value checked before anything is sent
        for request, full in planned:
            self.last_reply = self.sent(full, partial(self.link.request, request, idempotent=idempotent))
            self._tell_link(full)

    def _tell_link(self, values: Mapping[str, int]) -> None:
        if "slave_respond" in values:
            self.link.note_respond(self.address, bool(values["slave_respond"]))
        if "group_address" in values:
            self.link.note_group(self.address, values["group_address"])


class MksNativeDriver(MksDriver):
    """One MKS axis on a native RS485 bus."""

    access: MksNativeAccess

    def __init__(
        self,
        link: MksLink,
        address: int,
        *,
        device: str = "mks-servo42d",
        profile: MksProfile | str | None = None,
        clock: Clock | None = None,
        name: str = "",
        work_mode: int = st.WorkMode.SR_vFOC,
        microsteps: int | None = None,
        active: bool = True,
        firmware: FirmwareProfile | str | None = None,
    ) -> None:
        if not 1 <= address <= 255:
            raise CommandError(f"MKS slave address must be 1..255 (0 is broadcast), got {address}")
        self.link = link
        self.address = address
        self.active = active  #: ask for completion frames (0x8C active = 1)
        super().__init__(MksNativeAccess(link, address, model_params(device)), device=device, profile=profile,
                         clock=clock or link.clock, name=name or f"{device}@{address}", work_mode=work_mode,
                         microsteps=microsteps, firmware=firmware)
        #: the last completion frame of this drive (RunReply / CalibrationReply), None before any
        self.completion: Any = None
        self.completion_time = -math.inf
        self.completions = 0
        self._sub: Subscription[Any] | None = link.subscribe_completions(address, self._on_completion)
        self._returns: dict[int, Subscription[Any]] = {}  #: read command -> its timed returns' subscription
        #: read command -> the values its last timed return carried (V1.0.9 0x01)
        self.returned: dict[int, dict[str, int]] = {}

    def _on_completion(self, message: Any) -> None:
        self.completion = message
        self.completion_time = self.clock.now()
        self.completions += 1
        if isinstance(message, mks.RunReply) and message.function in (0xF4, 0xF5, 0xF6, 0xFD, 0xFE, 0x91):
            self._running = None

    @property
    def motion_complete(self) -> bool:
        """A completion frame arrived after the motion this host started last (active mode)."""
        return self.completions > self._sent_count

    def completed_since(self, since: float) -> bool:
        return self.completions > self._sent_count

    def prepare(self) -> None:
        """SR work mode, subdivision, and respond on + active as configured (0x8C)."""
        super().prepare()
        if self.image.get("slave_respond") != 1 or self.image.get("slave_active") != int(self.active):
            self.access.write_many({"slave_respond": 1, "slave_active": int(self.active)})

    def set_respond_active(self, respond: bool, active: bool) -> None:
        """0x8C: respond off silences the replies to run commands (queries still answer); active on sends
        completion frames (status 2 / 3) when a motion ends."""
        self.access.write_many({"slave_respond": int(respond), "slave_active": int(active)})
        self.active = active

    def set_group_address(self, group: int) -> None:
        """0x8D: the drive also executes commands sent to ``group`` (and answers none of them)."""
        self.write_param("group_address", group)

    def wait_motion(self, timeout: float = 30.0, *, poll: float = 0.01, recover: float = 0.25) -> st.MotorStatus:
        """Wait for the completion frame of the motion started last (active mode); without it - respond or
        active off, or the frame lost on the line - the motor status (read every ``recover`` s) tells."""
        if not self.active or self.link.rule.all_silent or self.address in self.link.rule.silent:
            return super().wait_motion(timeout, poll=poll)
        clock = self.clock
        start = clock.now()
        deadline = start + timeout
        next_check = start + recover
        while True:
            t0 = clock.now()
            self.link.poll(0.0)
            if self.motion_complete:
                self._running = None
                return st.MotorStatus.STOP
            now = clock.now()
            if now >= next_check:
                status = st.MotorStatus(self.access.read("motor_status"))
                if status is st.MotorStatus.STOP:  # the completion frame was lost: the status tells
                    self._running = None
                    return status
                next_check = now + recover
            if now >= deadline:
                raise MotionTimeout(f"{self.name}: no completion after {timeout} s")
            rest = poll - (clock.now() - t0)
            if rest > 0:
                self.link.poll(rest)
                left = poll - (clock.now() - t0)
                if left > 0:
                    clock.sleep(left)  # in process the bus waits no time: let the world run

    def read(self, key: str | int) -> int:
        """Read one parameter; the write-only settings too from firmware V1.0.6 (one 0x47)."""
        name = self.access.resolve(key)
        if name in _HELD and MKS_ALL_PARAMETERS in self.firmware.features:
            return self.access.read(name)
        return super().read(key)

    def verify_firmware(self) -> None:
        """The firmware check, then (V1.0.6+) what the drive holds by one 0x47: its settings fill the image
        (nothing the drive already holds is written again) and, unless one was given, its subdivision is the
        one the driver computes with."""
        if self._verified:
            return
        super().verify_firmware()
        if MKS_ALL_PARAMETERS in self.firmware.features:
            held = self.read_all_parameters()
            if not self.microsteps_given:
                self.microsteps = held["microsteps"]

    # -- read a configuration parameter (V1.0.8, 5.1.10) ------------------------------------------------
    def read_parameter(self, key: str | int) -> dict[str, int]:
        """0x00: the values the drive holds for the set command that carries ``key`` (all of its settings, by
        name; a later firmware's optional field is not part of the reply). They fill the image. A parameter
        the drive cannot read back (it answers FF FF) raises :class:`RegisterError`."""
        if MKS_READ_PARAMETER not in self.firmware.features:
            raise RegisterError(f"{self.name}: reading a configuration parameter (0x00) needs firmware v1.0.9 "
                                f"(V1.0.8); the joint's firmware is {self.firmware.firmware}")
        name = self.access.resolve(key)
        code = int(MKS_NATIVE.key(name).command)
        if code not in mks.PARAMETER_CODES:
            raise RegisterError(f"{self.name}: {name} (0x{code:02X}) is not a configuration parameter; read it "
                                "with read()")
        reply = self.link.request(mks.ReadParameter(self.address, code), idempotent=True)
        if not isinstance(reply, mks.ParameterReply):
            raise CommandError(f"{self.name}: no reply to 0x00 0x{code:02X}")
        if reply.param is None:
            raise RegisterError(f"{self.name}: the drive cannot read back 0x{code:02X} (it answered FF FF)")
        values = {n: v for n, v in _fields_of_request(mks.parameter_request(reply)).items()
                  if n not in OPTIONAL_FIELDS}
        self.access.remember(values)
        return values

    # -- timed returns (V1.0.9, 5.1.9) -----------------------------------------------------------------
    def timed_return(self, name: str, milliseconds: int, callback: Callable[[dict[str, int]], None] | None = None,
                     ) -> None:
        """0x01: the drive sends the read that carries ``name`` (e.g. "encoder_addition": 0x31) every
        ``milliseconds``, unasked; each arrives through the link's subscriptions as {parameter: value} to
        ``callback`` (and :attr:`returned`). 0 stops it."""
        if MKS_TIMED_RETURNS not in self.firmware.features:
            raise RegisterError(f"{self.name}: timed returns (0x01) need firmware v1.0.9; the joint's firmware is "
                                f"{self.firmware.firmware}")
        if not self.params[name].access.readable:
            raise RegisterError(f"{self.name}: {name} is not a read the drive can return by itself")
        code = int(MKS_NATIVE.key(name).command)
        if not 0 <= milliseconds <= 0xFFFF:
            raise CommandError(f"{self.name}: a timed return's period is 0..65535 ms, got {milliseconds}")
        old = self._returns.pop(code, None)
        if old is not None:
            old.cancel()
        names = fields_of(code)

        def deliver(message: Any) -> None:
            values = {n: int(getattr(message, MKS_NATIVE.key(n).field)) for n in names}
            self.returned[code] = values
            if callback is not None:
                callback(values)

        if milliseconds:
            self._returns[code] = self.link.subscribe_returns(self.address, code, deliver)
        try:
            self.link.request(mks.SetTimedReturn(self.address, code, milliseconds))
        except BaseException:
            sub = self._returns.pop(code, None)
            if sub is not None:
                sub.cancel()
            raise

    # -- all parameters at once (V1.0.6+, 5.7) ------------------------------------------------------
    def _require_blocks(self) -> None:
        if MKS_ALL_PARAMETERS not in self.firmware.features:
            raise RegisterError(f"{self.name}: reading/writing all parameters (0x46/0x47) needs firmware v1.0.6 or "
                                f"later; the joint's firmware is {self.firmware.firmware}")

    def read_all_parameters(self) -> dict[str, int]:
        """0x47: every configuration setting the drive holds (the write-only ones included), by name."""
        self._require_blocks()
        return self.access.read_all()  # what the drive holds fills the image: redundant writes are skipped

    def read_all_status(self) -> dict[str, int]:
        """0x48: every status value in one transaction, by name (5.7.3)."""
        self._require_blocks()
        reply = self.link.request(mks.ReadAllStatus(self.address), idempotent=True)
        if not isinstance(reply, mks.AllStatusReply):
            raise CommandError(f"{self.name}: no reply to 0x48")
        return blocks.unpack(blocks.ALL_STATUS, reply.params)

    def write_all_parameters(self, values: Mapping[str, int], *, confirm: bool = False) -> None:
        """0x46: write every configuration setting in one frame - ``values`` over what 0x47 reads now. It can
        change the address, baud rate and protocol (the host may lose the drive): needs ``confirm=True``."""
        if not confirm:
            raise ConfirmationRequired(f"{self.name}: 0x46 writes every setting at once (address, baud rate and "
                                       "protocol included); pass confirm=True if you mean it (nothing was sent)")
        self._require_blocks()
        unknown = sorted(set(values) - {n for n, _o, _s in blocks.ALL_PARAMETERS})
        if unknown:
            raise RegisterError(f"{self.name}: 0x46 carries no {', '.join(unknown)}")
        full = {**self.read_all_parameters(), "zero_mode_set_zero": self.image.get("zero_mode_set_zero", 0),
                **dict(values)}
        blocks.check(self.params, full)
        self.access.require({"home_mode": full["home_mode"]})  # a later firmware's value (hm_mode 2: V1.0.9)
        data = blocks.pack(blocks.ALL_PARAMETERS, full, mks.ALL_PARAMETERS_SIZE)
        self.access.sent(full, lambda: self.link.request(mks.WriteAllParameters(self.address, data)))
        for name, value in full.items():
            self._noted(name, value)
        self.access._tell_link(full)

    # -- frames for several drives ---------------------------------------------------------------
    def plan(self, values: Mapping[str, int], address: int | None = None) -> Any:
        """The request that would write ``values`` (one command) - for long packets, broadcast, groups."""
        request, _full = self.access.message(values, address)
        return request

    def plan_velocity(self, rpm: float, *, acceleration: int | None = None) -> Any:
        acc = self.acc_for(acceleration)
        value = self.speed_value(abs(rpm)) or (1 if rpm else 0)
        return self.plan(self._untimed({"speed_mode_direction": int(st.RunDirection.CCW if rpm >= 0
                                                                    else st.RunDirection.CW),
                                        "speed_mode_speed": value, "speed_mode_acc": acc}))

    def plan_move_to(self, position: int, *, speed: int | None = None, acceleration: int | None = None) -> Any:
        return self.plan(self._move_values("abs_axis", position, speed, acceleration))

    def plan_move_by(self, delta: int, *, speed: int | None = None, acceleration: int | None = None) -> Any:
        return self.plan(self._move_values("rel_axis", delta, speed, acceleration))

    def plan_move_pulses(self, pulses: int, *, speed: int | None = None, acceleration: int | None = None) -> Any:
        values = self._move_values("pulses", abs(pulses), speed, acceleration)
        values["position_mode1_direction"] = int(st.RunDirection.CCW if pulses >= 0 else st.RunDirection.CW)
        return self.plan(values)

    def note_sent(self, request: Any) -> None:
        """A run command for this drive went out without reply (broadcast, group, long packet): remember it."""
        if request.function not in _RUN_FUNCTION_MODES:
            return
        mode = _RUN_FUNCTION_MODES[request.function]
        _request, full = self.access.message(_fields_of_request(request))
        self.access.remember(full)
        speed = full[RUN_GROUPS[mode][0]]
        self._running = mode if speed else None
        self._sent_at = self.clock.now()
        self._sent_count = self.completions

    def broadcast(self, request: Any, drivers: Sequence[MksNativeDriver] = ()) -> None:
        """Send ``request`` to address 0: every drive executes it, none answers; ``drivers`` note it."""
        self.link.broadcast(request)
        for d in drivers:
            d.note_sent(request)

    def set_sync(self, on: bool) -> None:
        """0x4A (V1.0.8+): with ``on`` the drive holds each run command (reply status 5) until
        :meth:`sync_execute`; stops and 0xF7 still act at once."""
        self.write_param("sync_enable", int(on))

    def sync_execute(self, drivers: Sequence[MksNativeDriver] = (), *, repeat: int = 1) -> None:
        """0x4B (V1.0.8+) to address 0: every drive with 0x4A on starts its held run command; nobody answers.
        The manual suggests repeating it about 1 ms apart on a noisy bus (``repeat``); a repeat starts
        nothing new. ``drivers``: the drives it starts (they note the start time)."""
        self.access.require(("sync_enable",))
        for i in range(max(1, repeat)):
            if i:
                self.clock.sleep(0.001)
            self.link.broadcast(mks.SyncExecute(0))
        now = self.clock.now()
        for d in (self, *drivers):
            if d._running is not None:
                d._sent_at = now

    def send_group(self, group: int, request: Any, drivers: Sequence[MksNativeDriver] = ()) -> None:
        """Send ``request`` to a group address; ``drivers`` (the group's) note it."""
        self.link.send_group(group, request)
        for d in drivers:
            d.note_sent(request)

    def close(self) -> None:
        if self._sub is not None:
            self._sub.cancel()
            self._sub = None
        for sub in self._returns.values():
            sub.cancel()
        self._returns.clear()


class MksNativeHeartbeatDriver(MksHeartbeat, MksNativeDriver):
    """A native MKS axis whose firmware (V1.0.9) has the heartbeat protection: the watchdog capability."""


_RUN_FUNCTION_MODES = {0xF6: "speed", 0xFD: "pulses", 0xFE: "abs_pulses", 0xF4: "rel_axis", 0xF5: "abs_axis"}


def _fields_of_request(request: Any) -> dict[str, int]:
    """Parameter values carried by a request message (its command's fields)."""
    out: dict[str, int] = {}
    for name in fields_of(request.function):
        field = MKS_NATIVE.key(name).field
        if field:
            out[name] = int(getattr(request, field))
    return out


def long_packet(items: Sequence[tuple[MksNativeDriver, Any]]) -> None:
    """Send up to five drivers' commands in ONE 0xFC long packet (5.7): each drive executes its own, none
    answers, nothing is waited for; each driver notes the motion it started."""
    if not items:
        return
    link = items[0][0].link
    if any(d.link is not link for d, _ in items):
        raise CommandError("a long packet goes out on one bus: every driver must share the link")
    for d, request in items:
        if request.address != d.address:
            raise CommandError(f"{d.name}: the planned command is addressed to {request.address}, not {d.address}")
    link.send_long_packet([request for _, request in items])
    for d, request in items:
        d.note_sent(request)
