"""The compiled path: an env step's commands and state reads for in-process twins, in one call each.

Rule: the driver path (:class:`~joints.joint.Joint` -> driver -> parameter access -> link) is the
reference and the only path to hardware; this path changes which Python runs, never what happens.
It is built only for joints whose link hands requests to an in-process twin as objects (the sim's
direct path, :class:`~joints.link.base.DirectFraming`) and whose driver family it knows (eRob over
Modbus RTU; the ZLAC8015D over Modbus RTU, both wheels of a drive together). For each joint it keeps, per step:

* the joint's checks (:meth:`~joints.joint.Joint.position_command`, ``velocity_command``,
  ``torque_command``: limits, the last fault, the enable state) and the driver's range checks
  (:meth:`~joints.drivers.erob.ErobDriver.validate`) - the same calls, nothing sent on a refusal;
* the same requests, built by the parameter access (:meth:`~joints.drivers.access.ModbusAccess.write_request`)
  and sent by :meth:`~joints.link.base.Link.request`: the same counts, trace, retries, errors, the same
  simulated frame times (the direct framing over the timed line) and the same validation of every reply
  (``as_received`` + the rule's ``is_reply``);
* the driver's bookkeeping (what the drive holds, the recovery of a lost "start").

What it skips is the driver path's generic work of the steady case: the setup writes that are
already held (one compare, :meth:`~joints.drivers.erob.ErobDriver.steady_move`), the settle wait
that is over, the name -> register lookups of the status read (one prebuilt FC03). A joint step
that is not the steady case (a setting to write, the 500 ms after "enable" not over) goes through
the driver's own method, so the result is the driver path's in every case.
:attr:`CompiledPath.taken` counts the joint steps that took the compiled path.

A ZLAC8015D's two wheels are one drive: their reference is the rig's (:meth:`~joints.rig.Rig.set_velocities`,
:meth:`~joints.rig.Rig.read_states`), so a velocity command of both is the joints' checks, the drive's plan
(:meth:`~joints.drivers.zlac_modbus.ZlacDrive.velocity_plan`: range checks, mode, ramps) and its one or two
FC16s, each encoded by the registers' own ``to_words`` without the name lookups; both states are one
prebuilt FC03 decoded once. Its other commands, and a command to one wheel only, are the driver's own.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, TypeGuard

from joints.codecs import modbus as mb
from joints.drivers.access import ModbusAccess
from joints.drivers.base import sampled_at
from joints.drivers.erob import CMD_START, STATUS_NAMES
from joints.drivers.erob_modbus import ErobModbusDriver
from joints.drivers.zlac_modbus import STATUS_START, STATUS_WORDS, ZlacChannelDriver, ZlacDrive
from joints.errors import OutcomeUnknown
from joints.joint import Joint, JointState
from joints.link.base import DirectFraming
from joints.link.lane import LinkLane

__all__ = ["CompiledPath", "supported"]

ACTION_MODES = ("position", "velocity", "torque")


class _ErobModbus:
    """One eRob on a Modbus RTU direct path: target + start, target speed or target current; one FC03 state."""

    def __init__(self, joint: Joint, driver: ErobModbusDriver, access: ModbusAccess) -> None:
        self.joint = joint
        self.driver = driver
        self.access = access
        self.link = access.link
        self.lane = LinkLane(access.link)
        self.clock = driver.clock
        plan = access.block_plan(STATUS_NAMES)
        if len(plan) != 1:  # the status block is one FC03 on this register map
            raise ValueError(f"{joint.name}: the eRob status is {len(plan)} blocks, not one FC03")
        start, count = plan[0]
        self.status = mb.ReadHoldingRegisters(access.slave, start, count)  # what read_many sends
        self.status_start = start
        self.decode = access.table.decode_block
        self.start = access.write_request("start_operating", CMD_START)  # a constant command
        self.taken = 0
        #: the twin's one-call exchange (the sim's eRob: frames, physics and register ops in one compiled call,
        #: :meth:`LinkLane.exchange`), where the peer offers one
        fused = getattr(self.lane.framing.peer if self.lane.framing is not None else None, "fused", None)
        self.exchange: Any = fused(access.slave, self.lane.line) if callable(fused) and self.lane.line else None

    def _fused(self, requests: tuple[Any, ...], idempotent: bool) -> list[Any] | None:
        """The replies to ``requests`` by the twin's one-call exchange, or None (nothing sent)."""
        exchange = self.exchange
        return None if exchange is None else self.lane.exchange(exchange, requests, idempotent=idempotent)

    def command_all(self, mode: str, values: Sequence[float], skip: Sequence[bool]) -> None:
        if not skip[0]:
            self.command(mode, values[0])

    def states(self) -> list[JointState]:
        return [self.state()]

    def _write(self, name: str, value: int) -> None:
        request = self.access.write_request(name, value)
        if self._fused((request,), True) is None:
            self.lane.request(request, idempotent=True)
        self.driver.note_written(name, value)

    def command(self, mode: str, value: float) -> None:
        joint, driver = self.joint, self.driver
        if mode == "position":
            target, speed, acc, dec = joint.position_command(value)
            if driver.steady_move(speed, acc, dec):
                driver.validate(target_absolute_position=target)
                request = self.access.write_request("target_absolute_position", target)
                if self._fused((request, self.start), False) is not None:  # both in one call
                    driver.note_written("target_absolute_position", target)
                else:
                    self.lane.request(request, idempotent=True)
                    driver.note_written("target_absolute_position", target)
                    try:  # a command: never retried
                        self.lane.request(self.start, idempotent=False)
                    except OutcomeUnknown as exc:
                        driver.start_unknown(target, exc)
                self.taken += 1
            else:
                driver.move_to(target, speed=speed, acceleration=acc, deceleration=dec)
            joint.note_contact()
        elif mode == "velocity":
            speed, ramp = joint.velocity_command(value)
            if driver.steady_velocity(ramp, ramp):
                driver.validate(target_speed=speed)
                self._write("target_speed", speed)
                self.taken += 1
            else:
                driver.set_velocity(speed, acceleration=ramp, deceleration=ramp)
        else:
            current = joint.torque_command(value)
            if driver.steady_current():
                driver.validate(target_current=current)
                self._write("target_current", current)
                self.taken += 1
            else:
                driver.set_current(current)
            joint.note_contact()

    def state(self) -> JointState:
        clock = self.clock
        t0 = clock.now()
        replies = self._fused((self.status,), True)
        reply = self.lane.request(self.status, idempotent=True) if replies is None else replies[0]
        assert isinstance(reply, mb.ReadRegistersReply)
        values = self.decode(self.status_start, reply.values)
        return self.joint.to_si(self.driver.state_from(values, sampled_at(t0, clock.now())))


class _Block:
    """One FC16 of fixed contiguous registers (what ``ModbusAccess.write_many`` sends for them)."""

    def __init__(self, access: ModbusAccess, names: Sequence[str]) -> None:
        table = access.table
        self.start, _ = table.encode_block(dict.fromkeys(names, 0))  # raises unless contiguous
        self.registers = tuple(sorted((table[n] for n in names), key=lambda r: r.address))
        self.slave = access.slave

    def request(self, values: dict[str, int]) -> mb.WriteMultipleRegisters:
        words: list[int] = []
        for reg in self.registers:
            words.extend(reg.to_words(values[reg.name]))  # range-checked, as encode_block does
        return mb.WriteMultipleRegisters(self.slave, self.start, tuple(words))


class _ZlacModbus:
    """Both wheels of one ZLAC8015D on a Modbus RTU direct path: one FC16 of both speeds (and one of the
    ramps when they change), one FC03 of both states (the rig's :meth:`~joints.rig.Rig.set_velocities`
    and :meth:`~joints.rig.Rig.read_states`)."""

    def __init__(self, joints: Sequence[Joint], drive: ZlacDrive) -> None:
        self.joints = tuple(joints)
        self.drivers = [j.driver for j in joints if isinstance(j.driver, ZlacChannelDriver)]
        self.drive = drive
        access = drive.access
        self.link = access.link
        self.lane = LinkLane(access.link)
        self.clock = drive.clock
        self.status = mb.ReadHoldingRegisters(access.slave, STATUS_START, STATUS_WORDS)  # what read_status sends
        self.decode = access.table.decode_block
        self.ramps = _Block(access, [f"{stem}_{side}" for stem in ("acceleration_time", "deceleration_time")
                                     for side in ("left", "right")])
        self.targets = _Block(access, ["target_velocity_left", "target_velocity_right"])
        self.taken = 0

    def _write(self, block: _Block, values: dict[str, int]) -> None:
        self.lane.request(block.request(values), idempotent=True)
        self.drive.note_written(values)

    def command_all(self, mode: str, values: Sequence[float], skip: Sequence[bool]) -> None:
        joints = self.joints
        if mode == "velocity" and not any(skip):
            checked = [j.velocity_command(v) for j, v in zip(joints, values)]
            ramps, targets = self.drive.velocity_plan({d.channel: c for d, c in zip(self.drivers, checked)})
            if ramps is not None:
                self._write(self.ramps, ramps)
            self._write(self.targets, targets)
            self.taken += len(joints)
            return
        for j, v, s in zip(joints, values, skip):  # the driver's own methods
            if s:
                continue
            if mode == "velocity":  # one wheel: as the rig sends it
                speed, ramp = j.velocity_command(v)
                j.driver.set_velocity(speed, acceleration=ramp, deceleration=ramp)
            elif mode == "position":
                j.move_to(v)
            else:
                j.set_torque(v)

    def states(self) -> list[JointState]:
        clock = self.clock
        t0 = clock.now()
        self.drive.identify()  # once per drive: a no-op after the first
        reply = self.lane.request(self.status, idempotent=True)
        assert isinstance(reply, mb.ReadRegistersReply)
        block = self.decode(STATUS_START, reply.values)
        t = sampled_at(t0, clock.now())
        return [j.to_si(d.state_from(block, t)) for j, d in zip(self.joints, self.drivers)]


_Stepper = _ErobModbus | _ZlacModbus


def _direct(access: object) -> TypeGuard[ModbusAccess]:
    """Modbus RTU parameters on a link that hands requests to an in-process twin as objects."""
    return isinstance(access, ModbusAccess) and isinstance(access.link.framing, DirectFraming)


def _stepper(joint: Joint) -> _ErobModbus | None:
    driver = joint.driver
    if isinstance(driver, ErobModbusDriver):
        access = driver.access
        if _direct(access):
            return _ErobModbus(joint, driver, access)
    return None


def _zlac_drive(joint: Joint) -> ZlacDrive | None:
    driver = joint.driver
    if isinstance(driver, ZlacChannelDriver) and _direct(driver.drive.access):
        return driver.drive
    return None


def supported(joint: Joint) -> bool:
    """Whether the compiled path can step ``joint`` (a known family on an in-process direct path; a ZLAC8015D
    wheel together with its drive's other wheel)."""
    return _zlac_drive(joint) is not None or _stepper(joint) is not None


def _steppers(joints: Sequence[Joint]) -> list[tuple[tuple[int, ...], _Stepper]]:
    """(joint indices, stepper) in the order of each stepper's first joint; raises where a joint cannot be stepped."""
    units: list[tuple[list[int], ZlacDrive | _ErobModbus | None]] = []
    drives: dict[int, list[int]] = {}
    for i, j in enumerate(joints):
        drive = _zlac_drive(j)
        if drive is None:
            units.append(([i], _stepper(j)))
        elif id(drive) in drives:
            drives[id(drive)].append(i)
        else:
            units.append((drives.setdefault(id(drive), [i]), drive))
    out: list[tuple[tuple[int, ...], _Stepper]] = []
    missing: list[str] = []
    for idx, s in units:
        members = [joints[i] for i in idx]
        if isinstance(s, ZlacDrive):
            if sorted(m.driver.channel for m in members) != sorted(s.channels):  # type: ignore[attr-defined]
                missing.extend(m.name for m in members)  # one wheel of a drive: the rig commands it alone
            else:
                out.append((tuple(idx), _ZlacModbus(members, s)))
        elif s is None:
            missing.extend(m.name for m in members)
        else:
            out.append((tuple(idx), s))
    if missing:
        raise ValueError(f"the compiled path cannot step joints {missing} (not an in-process twin of a "
                         "family it knows, or one wheel of a two-wheel drive); use the driver path")
    return out


class CompiledPath:
    """The commands and state reads of a list of joints, each joint's in order (see the module docstring)."""

    def __init__(self, joints: Sequence[Joint]) -> None:
        self._joints = list(joints)
        self._units = _steppers(joints)
        self._steppers = [s for _, s in self._units]

    @classmethod
    def build(cls, joints: Sequence[Joint]) -> CompiledPath | None:
        """The compiled path of ``joints``, or None where one of them is not :func:`supported`."""
        if not joints or not all(supported(j) for j in joints):
            return None
        try:
            return cls(joints)
        except ValueError:  # one wheel of a two-wheel drive
            return None

    @property
    def taken(self) -> int:
        """Joint steps (commands) sent the compiled way, not through the driver's own method."""
        return sum(s.taken for s in self._steppers)

    @property
    def fused(self) -> int:
        """Requests sent by a twin's one-call exchange (:meth:`~joints.link.lane.LinkLane.exchange`)."""
        return sum(s.lane.fused for s in self._steppers)

    @property
    def lane_taken(self) -> int:
        """Requests sent on the direct lane (:class:`~joints.link.lane.LinkLane`), not through ``Link.request``."""
        return sum(s.lane.taken for s in self._steppers)

    def command(self, mode: str, values: Sequence[float], skip: Sequence[bool] | None = None) -> None:
        """Joint ``i`` gets ``values[i]`` (rad | rad/s | N*m per ``mode``) unless ``skip[i]``, in joint order."""
        if mode not in ACTION_MODES:
            raise ValueError(f"mode {mode!r} is not one of {ACTION_MODES}")
        for idx, s in self._units:
            s.command_all(mode, [values[i] for i in idx], [skip is not None and skip[i] for i in idx])

    def states(self) -> list[JointState]:
        """Every joint's state, read in joint order (as ``[j.state() for j in joints]``; the wheels of a
        ZLAC8015D as ``rig.read_states``: one read of their drive)."""
        out: list[Any] = [None] * len(self._joints)
        for idx, s in self._units:
            for i, state in zip(idx, s.states()):
                out[i] = state
        return out

    def __repr__(self) -> str:
        names: list[Any] = [j.name for j in self._joints]
        return f"CompiledPath({names})"
