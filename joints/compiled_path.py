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

Where the peer offers a one-call exchange (the sim's eRob twins: :mod:`joints.sim.erob_exchange`), an eRob's
steady requests - a command's writes, the status read; every eRob's of a rig on one line together - go in ONE
compiled call (frames, physics and the drive's register ops), by :meth:`~joints.link.lane.LinkLane.exchange`,
which falls back to the requests one by one before anything is sent where the case is not steady;
:attr:`CompiledPath.fused` counts the requests it carried. An env's whole steady step - the command's writes, the
env's wait for its tick (what ``RigEnv._wait_until``, ``Rig.sleep`` and ``World.hold`` do: a hold row in the call,
:func:`joints.sim.line_exchange.hold`) and the status reads - goes in ONE such call by :meth:`CompiledPath.step`
(:attr:`CompiledPath.steps_taken` counts them); anything that would make the wait more than the world's hold (a
keep-alive read due, another clock) or the step not steady sends nothing there, and the three go one after the other.

A ZLAC8015D's two wheels are one drive: their reference is the rig's (:meth:`~joints.rig.Rig.set_velocities`,
:meth:`~joints.rig.Rig.read_states`), so a velocity command of both is the joints' checks, the drive's plan
(:meth:`~joints.drivers.zlac_modbus.ZlacDrive.velocity_plan`: range checks, mode, ramps) and its one or two
FC16s, each encoded by the registers' own ``to_words`` without the name lookups; both states are one
prebuilt FC03 decoded once. Its other commands, and a command to one wheel only, are the driver's own.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any, TypeGuard

from joints.codecs import modbus as mb
from joints.devices.zlac.registers import ControlMode
from joints.drivers import zlac_modbus as zm
from joints.drivers.access import ModbusAccess
from joints.drivers.base import sampled_at
from joints.drivers.erob import CMD_START, STATUS_NAMES
from joints.drivers.erob_modbus import ErobModbusDriver
from joints.drivers.zlac_modbus import STATUS_START, STATUS_WORDS, ZlacChannelDriver, ZlacDrive
from joints.errors import EncodeError, OutcomeUnknown
from joints.joint import Joint, JointState
from joints.link.base import DirectFraming
from joints.link.lane import LinkLane
from joints.transports.serial_sim import Deferred

__all__ = ["CompiledPath", "CompiledRigs", "supported"]

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
        self._status_alone = (self.status,)
        self.status_start = start
        self.decode = access.table.decode_block
        #: what the driver's status decode gives names to: the registers wholly in the block, in address order
        self._names = tuple(self.decode(start, (0,) * count))
        self._registers = tuple(access.table[n] for n in self._names)
        self._proven: Any = None  #: the twin's registers of a status reply proven to be these (by identity)
        self.start = access.write_request("start_operating", CMD_START)  # a constant command
        self.taken = 0
        self.taken_values = 0  #: status reads whose state came from the values, not the words (:meth:`_values`)
        #: the twin's one-call exchange (the sim's eRob: frames, physics and register ops in one compiled call,
        #: :meth:`LinkLane.exchange`), where the peer offers one
        fused = getattr(self.lane.framing.peer if self.lane.framing is not None else None, "fused", None)
        self.exchange: Any = fused(access.slave, self.lane.line) if callable(fused) and self.lane.line else None
        #: the status read by it: a reply known by its values (:meth:`state_of`)
        self._read = None if self.exchange is None else functools.partial(self.exchange.run, lazy=True)

    def carried(self) -> tuple[Any, list[Any]] | None:
        """(the compiled world, [the twin]) whose every frame the one-call exchange carries; None: it has none."""
        exchange = self.exchange
        return None if exchange is None else (exchange.world, [exchange.firmware])

    def _fused(self, requests: tuple[Any, ...], idempotent: bool) -> list[Any] | None:
        """The replies to ``requests`` by the twin's one-call exchange, or None (nothing sent)."""
        exchange = self.exchange
        return None if exchange is None else self.lane.exchange(exchange.run, requests, idempotent=idempotent)

    def plan(self, mode: str, value: float) -> tuple[tuple[Any, ...], str, int] | None:
        """A command's checks (:meth:`command`'s) and, in the steady case, its requests, the parameter it sets
        and the value; None where it is not the steady case (nothing sent either way)."""
        joint, driver, access = self.joint, self.driver, self.access
        if mode == "position":
            target, speed, acc, dec = joint.position_command(value)
            if not driver.steady_move(speed, acc, dec):
                return None
            driver.validate(target_absolute_position=target)
            return (access.write_request("target_absolute_position", target), self.start), \
                "target_absolute_position", target
        if mode == "velocity":
            speed, ramp = joint.velocity_command(value)
            if not driver.steady_velocity(ramp, ramp):
                return None
            driver.validate(target_speed=speed)
            return (access.write_request("target_speed", speed),), "target_speed", speed
        current = joint.torque_command(value)
        if not driver.steady_current():
            return None
        driver.validate(target_current=current)
        return (access.write_request("target_current", current),), "target_current", current

    def done(self, mode: str, name: str, value: int, before: float, after: float) -> None:
        """The bookkeeping of a planned command sent between the clock instants ``before`` and ``after``."""
        self.driver.note_written(name, value)
        # the joint's contact: velocity_command's before the frames, note_contact's after them
        self.joint.note_contact(before if mode == "velocity" else after)
        self.taken += 1

    def state_of(self, reply: Any, t0: float, t1: float) -> JointState:
        """The state from the status read's ``reply``, sent at ``t0`` and answered at ``t1`` (clock instants)."""
        if type(reply) is mb.ReadRegistersReply:
            values = self.decode(self.status_start, reply.values)
        else:
            values = self._values(reply)
        return self.joint.to_si(self.driver.state_from(values, sampled_at(t0, t1)))

    def _values(self, reply: Any) -> dict[str, int]:
        """What the status decode gives for a reply known by its values (a twin's
        :class:`~joints.transports.serial_sim.Deferred` reply: ``registers``, the registers its words pack, in
        block order; ``values``, each an int within its register's type): those values by name where the
        registers are the ones the decode names (equal registers: the same address, type and word order - the
        words unpack to the values packed), else the decode of its words."""
        assert isinstance(reply, Deferred)
        registers = getattr(reply, "registers", None)
        if registers is not self._proven:
            if registers != self._registers:
                words = reply.message()
                assert isinstance(words, mb.ReadRegistersReply)
                return self.decode(self.status_start, words.values)
            self._proven = registers
        self.taken_values += 1
        return dict(zip(self._names, reply.values))  # type: ignore[attr-defined]

    def command_all(self, mode: str, values: Sequence[float], skip: Sequence[bool]) -> None:
        if not skip[0]:
            self.command(mode, values[0])

    def states(self) -> list[JointState]:
        return [self.state()]

    def step(self, mode: str, values: Sequence[float], tick: float) -> tuple[list[JointState], float] | None:
        """:meth:`CompiledPath.step` of this joint: its steady command, the hold to ``tick`` and the status read
        in one call of the one-call exchange; None (nothing sent) where that is not the steady case."""
        exchange = self.exchange
        if exchange is None:
            return None
        try:
            p = self.plan(mode, values[0])
        except Exception:  # noqa: BLE001 - a refusal: the command's own way raises it again
            return None
        if p is None:
            return None
        sent, name, value = p
        n = len(sent)
        before = self.clock.now()
        run = functools.partial(exchange.run, lazy=True, hold=(n, tick))
        replies = self.lane.exchange(run, (*sent, self.status), idempotent=True)
        if replies is None:
            return None
        clocks = exchange.clocks
        self.done(mode, name, value, before, clocks[n - 1])
        remaining, held = exchange.held
        return [self.state_of(replies[n], held, clocks[n])], remaining

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
        run = self._read
        replies = None if run is None else self.lane.exchange(run, self._status_alone, idempotent=True)
        reply = self.lane.request(self.status, idempotent=True) if replies is None else replies[0]
        return self.state_of(reply, t0, clock.now())


class _Block:
    """One FC16 of fixed contiguous registers, named in address order (what ``ModbusAccess.write_many`` sends)."""

    def __init__(self, access: ModbusAccess, names: Sequence[str]) -> None:
        table = access.table
        self.start, _ = table.encode_block(dict.fromkeys(names, 0))  # raises unless contiguous
        self.registers = tuple(table[n] for n in names)
        if [r.address for r in self.registers] != sorted(r.address for r in self.registers):
            raise ValueError(f"_Block: {list(names)} are not in address order")
        self.names = tuple(names)
        self.slave = access.slave
        #: every register one word: its word is its checked value & 0xFFFF (``to_words`` without the tuple)
        self._checks = tuple(r.check for r in self.registers) if all(r.words == 1 for r in self.registers) else None

    def request(self, values: Sequence[int]) -> mb.WriteMultipleRegisters:
        """The FC16 of ``values`` (one per register, in :attr:`names`' order), each encoded as its register's
        ``to_words`` encodes it (range-checked, as ``encode_block`` does)."""
        checks = self._checks
        if checks is not None:
            return mb.WriteMultipleRegisters(self.slave, self.start,
                                             tuple([check(v) & 0xFFFF for check, v in zip(checks, values)]))
        words: list[int] = []
        for reg, v in zip(self.registers, values):
            words.extend(reg.to_words(v))
        return mb.WriteMultipleRegisters(self.slave, self.start, tuple(words))


class _ZlacModbus:
    """Both wheels of one ZLAC8015D on a Modbus RTU direct path: one FC16 of both speeds (and one of the
    ramps when they change), one FC03 of both states (the rig's :meth:`~joints.rig.Rig.set_velocities`
    and :meth:`~joints.rig.Rig.read_states`)."""

    #: the drive's control mode (0x200D) in velocity mode (:meth:`ZlacDrive.velocity_words`' steady case)
    VELOCITY = int(ControlMode.VELOCITY)

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
        self.ramps = _Block(access, zm.RAMP_NAMES)
        self.targets = _Block(access, zm.TARGET_NAMES)
        #: the joint index of the left and of the right wheel (velocity_words takes them in that order)
        channels = [d.channel for d in self.drivers]
        self._sides = (channels.index("left"), channels.index("right"))
        self._pairs = tuple(zip(self.joints, self.drivers))  #: (joint, its wheel's driver), in joint order
        #: the steady FC16s in one compiled call (frames, physics, the twin's ops) where the twin offers it
        self.exchange = _velocity_exchange(self.lane, access.slave)
        self.taken = 0
        #: the caller's last :meth:`states` ``settle`` (its reads' next access to the world): :meth:`step`'s read
        self._settle = False

    def carried(self) -> tuple[Any, list[Any]] | None:
        """(the compiled world, [the twin]) whose every frame the one-call exchange carries over a timed line;
        None: it has none (:func:`_hold_sleeps`)."""
        carried = getattr(self.exchange, "carried", None)
        return carried() if callable(carried) else None

    def _write(self, block: _Block, values: tuple[int, ...]) -> None:
        self.lane.request(block.request(values), idempotent=True)
        self.drive.note_words(block.names, values)

    def _send(self, ramps: tuple[int, ...] | None, targets: tuple[int, ...]) -> None:
        """The ramp FC16 (if any) and the target FC16: in one exchange where it takes them, else one by one."""
        ramp_block, target_block = self.ramps, self.targets
        exchange = self.exchange
        if exchange is not None:
            ramp = None if ramps is None else ramp_block.request(ramps)  # (in the order the lane's way builds them)
            target = target_block.request(targets)
            if exchange.write((target,) if ramp is None else (ramp, target)):
                note = self.drive.note_words
                if ramps is not None:
                    note(ramp_block.names, ramps)
                note(target_block.names, targets)
                return
        if ramps is not None:
            self._write(ramp_block, ramps)
        self._write(target_block, targets)

    def command_all(self, mode: str, values: Sequence[float], skip: Sequence[bool]) -> None:
        joints = self.joints
        if mode == "velocity" and not any(skip):
            checked = [j.velocity_command(v) for j, v in zip(joints, values)]
            left, right = self._sides
            ramps, targets = self.drive.velocity_words(checked[left], checked[right])
            self._send(ramps, targets)
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

    def states(self, settle: bool = False) -> list[JointState]:
        """Both wheels' states (one FC03); ``settle``: the caller's next access to the world runs its booked time
        (:meth:`CompiledPath.states`; kept for :meth:`step`'s read, the caller's next read)."""
        self._settle = settle
        t0 = self.clock.now()
        self.drive.identify()  # once per drive: a no-op after the first
        exchange = self.exchange
        done, reply = exchange.read(self.status, settle=settle) if exchange is not None else (False, None)
        if not done:
            reply = self.lane.request(self.status, idempotent=True)
        return self._states_of(reply, t0)

    def _states_of(self, reply: Any, t0: float) -> list[JointState]:
        """Both wheels' states from the status read's ``reply``, sent at clock instant ``t0`` (answered now)."""
        assert isinstance(reply, mb.ReadRegistersReply)
        block = self.decode(STATUS_START, reply.values)
        t = sampled_at(t0, self.clock.now())
        return [j.to_si(d.state_from(block, t)) for j, d in self._pairs]

    def step(self, mode: str, values: Sequence[float], tick: float) -> tuple[list[JointState], float] | None:
        """:meth:`CompiledPath.step` of both wheels: the steady velocity command (:meth:`command_all`'s: the ramp
        FC16 where the ramps change, the target FC16), the hold to ``tick`` and the status read (:meth:`states`'s,
        with the caller's last ``settle``) in one call of the twin's exchange
        (:meth:`~joints.sim.zlac_exchange.ZlacExchange.step`); None (nothing sent) where that is not the steady
        case: another mode, the drive not yet identified or not in velocity mode, a refusal of the checks."""
        exchange = self.exchange
        drive = self.drive
        if exchange is None or mode != "velocity" or drive.lines is None or drive.state.mode != self.VELOCITY:
            return None
        steady = exchange.steady(self.status)
        if steady is None:  # (asked before the plan: the command's own way plans it once)
            return None
        try:
            checked = [j.velocity_command(v) for j, v in zip(self.joints, values)]
            left, right = self._sides
            ramps, targets = drive.velocity_words(checked[left], checked[right])
            target = self.targets.request(targets)
            writes = (target,) if ramps is None else (self.ramps.request(ramps), target)
        except Exception:  # noqa: BLE001 - a refusal: the command's own way raises it again
            return None
        got = exchange.step(steady, writes, self.status, tick, settle=self._settle)
        if got is None:
            return None
        reply, remaining, held = got
        if ramps is not None:
            drive.note_words(self.ramps.names, ramps)
        drive.note_words(self.targets.names, targets)
        self.taken += len(self.joints)
        return self._states_of(reply, held), remaining


def _velocity_exchange(lane: LinkLane, slave: int) -> Any:
    """The one-call exchange the twin at ``slave`` behind ``lane``'s in-process peer offers for a steady velocity
    command (``velocity_exchange(lane, slave)``, e.g. :class:`joints.sim.zlac_exchange.ZlacExchange`), or None."""
    slaves = getattr(getattr(lane.framing, "peer", None), "slaves", None)
    front = slaves.get(slave) if isinstance(slaves, dict) else None
    make = getattr(getattr(front, "firmware", None), "velocity_exchange", None)
    return make(lane, slave) if callable(make) else None


_Stepper = _ErobModbus | _ZlacModbus


def _direct(access: object) -> TypeGuard[ModbusAccess]:
    """Modbus RTU parameters on a link that hands requests to an in-process twin as objects."""
    return isinstance(access, ModbusAccess) and isinstance(access.link.framing, DirectFraming)


def _stepper(joint: Joint) -> Any:
    driver = joint.driver
    if isinstance(driver, ErobModbusDriver):
        access = driver.access
        if _direct(access):
            return _ErobModbus(joint, driver, access)
        return None
    own = getattr(driver, "compiled_step", None)  # a driver's own step (an eRob on CAN: joints.drivers.erob_can_steady)
    return own(joint) if callable(own) else None


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


def _erob_batch(steppers: Sequence[_Stepper]) -> list[_ErobModbus] | None:
    """Two or more eRobs, one per joint in joint order, on one link whose twins share one line and world:
    their steps go in one call of their one-call exchange (:func:`_command_batch`, :func:`_states_batch`)."""
    units = [s for s in steppers if isinstance(s, _ErobModbus) and s.exchange is not None]
    if len(units) < 2 or len(units) != len(steppers):
        return None
    first = units[0]
    same = all(s.link is first.link and s.exchange.line is first.exchange.line
               and s.exchange.world is first.exchange.world for s in units)
    return units if same and getattr(first.exchange.world, "compiled", False) else None  # (it needs the compiled world)


_Planned = list[tuple[_ErobModbus, tuple[tuple[Any, ...], str, int]]]


def _plan_all(units: Sequence[_ErobModbus], mode: str, values: Sequence[float], skip: Sequence[bool] | None = None
              ) -> tuple[_Planned, list[Any], list[Any]] | None:
    """Every joint's steady command but the skipped ones (:meth:`_ErobModbus.plan`: its checks and requests), all
    its requests and, per request, the exchange of its drive; None (nothing sent) where one joint is not the
    steady case or its checks refuse (its own command raises that again, in its turn)."""
    planned: _Planned = []
    requests: list[Any] = []
    exchanges: list[Any] = []
    for k, s in enumerate(units):
        if skip is not None and skip[k]:
            continue
        try:
            p = s.plan(mode, values[k])
        except Exception:  # noqa: BLE001 - a refusal: raised again by the joint's own command
            return None
        if p is None:
            return None
        planned.append((s, p))
        requests.extend(p[0])
        exchanges.extend([s.exchange] * len(p[0]))
    return planned, requests, exchanges


def _note_done(mode: str, planned: _Planned, clocks: Sequence[float], before: float) -> None:
    """Each planned command's bookkeeping (:meth:`_ErobModbus.done`), sent from ``before`` (the clock before the
    call, then after the command before it) to the clock after its last request (``clocks``: after each request
    of the call, the commands' first)."""
    at = 0
    for s, (reqs, name, value) in planned:
        at += len(reqs)
        after = clocks[at - 1]
        s.done(mode, name, value, before, after)
        before = after


def _states_read(units: Sequence[_ErobModbus], replies: Sequence[Any], clocks: Sequence[float], before: float
                 ) -> list[JointState]:
    """Each joint's state from its status read's reply (``replies``, ``clocks``: each read's, in joint order),
    stamped from ``before`` (the clock before the reads) or the read before it, to the clock after its own."""
    out: list[JointState] = []
    for s, reply, after in zip(units, replies, clocks):
        out.append(s.state_of(reply, before, after))
        before = after
    return out


def _command_batch(units: list[_ErobModbus], mode: str, values: Sequence[float], skip: Sequence[bool] | None) -> None:
    """:meth:`CompiledPath.command` of one eRob per joint: the steady commands of the joints up to the first that
    is not the steady case (or whose checks refuse it) go in one call, after each joint's checks; from that
    joint on, joint by joint, each its own way (so a refusal is raised by that joint's own command, after the
    joints before it were sent, as the joint by joint path raises it)."""
    planned: list[tuple[_ErobModbus, tuple[tuple[Any, ...], str, int]]] = []
    rest = len(units)
    for k, s in enumerate(units):
        if skip is not None and skip[k]:
            continue
        try:
            p = s.plan(mode, values[k])
        except Exception:  # noqa: BLE001 - a refusal: this joint's own command raises it again, in its turn
            p = None
        if p is None:
            rest = k
            break
        planned.append((s, p))
    if planned:
        first = planned[0][0]
        requests = [r for _, p in planned for r in p[0]]
        exchanges = [s.exchange for s, p in planned for _ in p[0]]
        t0 = first.clock.now()
        replies = first.lane.exchange(functools.partial(first.exchange.run, exchanges=exchanges), requests,
                                      idempotent=True)  # (one request alone: a target write, idempotent)
        if replies is None:  # not the steady case: joint by joint, each its own way (its checks again)
            for s, _ in planned:
                s.command(mode, values[units.index(s)])
        else:
            _note_done(mode, planned, first.exchange.clocks, t0)
    for k in range(rest, len(units)):  # from the first joint that is not the steady case (or refuses): its own way
        if skip is None or not skip[k]:
            units[k].command(mode, values[k])


def _states_batch(units: list[_ErobModbus]) -> list[JointState] | None:
    """Every joint's state by one call of the twins' one-call exchange (the reads joint by joint, the state of
    each stamped with its own transaction's instants); None (nothing sent) where that is not the steady case."""
    first = units[0]
    t0 = first.clock.now()
    run = functools.partial(first.exchange.run, exchanges=[s.exchange for s in units], lazy=True)
    replies = first.lane.exchange(run, [s.status for s in units], idempotent=True)
    if replies is None:
        return None
    return _states_read(units, replies, first.exchange.clocks, t0)


def _step_batch(units: list[_ErobModbus], mode: str, values: Sequence[float], tick: float
                ) -> tuple[list[JointState], float] | None:
    """:meth:`CompiledPath.step` of one eRob per joint on one line (:func:`_erob_batch`): every joint's steady
    command (:func:`_command_batch`'s), the hold to ``tick`` and every status read (:func:`_states_batch`'s) in
    one call; None (nothing sent) where one joint is not the steady case or its checks refuse."""
    got = _plan_all(units, mode, values)
    if got is None:
        return None
    planned, requests, exchanges = got
    first = units[0]
    n = len(requests)
    requests += [s.status for s in units]
    exchanges += [s.exchange for s in units]
    t0 = first.clock.now()
    run = functools.partial(first.exchange.run, exchanges=exchanges, lazy=True, hold=(n, tick))
    replies = first.lane.exchange(run, requests, idempotent=True)
    if replies is None:
        return None
    clocks = first.exchange.clocks
    _note_done(mode, planned, clocks, t0)
    remaining, held = first.exchange.held
    return _states_read(units, replies[n:], clocks[n:], held), remaining


def _hold_sleeps(steppers: Sequence[_Stepper]) -> Any:
    """Where every stepper's steady requests go in a one-call exchange (its ``carried()``: the compiled world the
    exchange runs and the twins whose every frame it carries; None where it has none), on one compiled world
    every drive of which is carried (so every frame reaches a drive over a timed line, which settles the world
    first): the world's sleeps book their time (``World.hold``) and the env's period hold runs at the start of
    the next call (the status read's) - one compiled call fewer per step, the same bits."""
    held = [carried() if callable(carried := getattr(s, "carried", None)) else None for s in steppers]
    if not held or any(h is None for h in held):
        return None
    world = held[0][0]  # type: ignore[index]
    if not getattr(world, "compiled", False) or any(h[0] is not world for h in held):  # type: ignore[index]
        return None
    ours = {id(twin) for h in held for twin in h[1]}  # type: ignore[index]
    if all(id(twin) in ours for twin in world.emulators()):
        world.hold_sleeps = True
        return world
    return None


class CompiledPath:
    """The commands and state reads of a list of joints, each joint's in order (see the module docstring)."""

    def __init__(self, joints: Sequence[Joint]) -> None:
        self.steps_taken = 0  #: env steps that went in one call (:meth:`step`)
        self._joints = list(joints)
        self._units = _steppers(joints)
        self._steppers = [s for _, s in self._units]
        self._batch = _erob_batch(self._steppers)
        #: the world whose sleeps the steppers' exchanges hold (:func:`_hold_sleeps`), or None
        self._world = _hold_sleeps(self._steppers)
        #: a whole env step in one call (:meth:`step`): the batch's, or the one stepper's own ``step``
        self._step: Any = None
        if self._world is not None:
            if self._batch is not None:
                self._step = functools.partial(_step_batch, self._batch)
            elif len(self._steppers) == 1:
                self._step = getattr(self._steppers[0], "step", None)

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
        if self._batch is not None:
            _command_batch(self._batch, mode, values, skip)
            return
        for idx, s in self._units:
            s.command_all(mode, [values[i] for i in idx], [skip is not None and skip[i] for i in idx])

    @property
    def steps(self) -> bool:
        """Whether :meth:`step` may take an env's whole step (else it always answers None)."""
        return self._step is not None

    def step(self, mode: str, values: Sequence[float], skip: Sequence[bool] | None, tick: float, rig: Any
             ) -> tuple[list[JointState], float] | None:
        """An env step in one call of the twins' one-call exchange where it is the steady case: every joint's
        command (:meth:`command`), the env's wait for its tick at rig time ``tick`` (``RigEnv._wait_until``:
        ``remaining``, the tick less the clock after the command; where > 0, ``rig``'s sleep of it, which the
        world holds) and every joint's state (:meth:`states`) - the same requests, frames, substeps and bits as
        those three one after the other. Returns (the states, ``remaining``), or None with nothing sent where it
        is not the steady case: a joint skipped or not steady (or refused by its checks), the rig's sleep not the
        world's hold alone (a keep-alive read due, another clock) - then the caller does the three."""
        if mode not in ACTION_MODES:
            raise ValueError(f"mode {mode!r} is not one of {ACTION_MODES}")
        fused = self._step
        if fused is None or (skip is not None and any(skip)):
            return None
        world = self._world
        if rig.clock is not world.clock or not world.hold_sleeps or not rig.sleeps_quietly(tick):
            return None
        got: tuple[list[JointState], float] | None = fused(mode, values, tick)
        if got is not None:
            self.steps_taken += 1
        return got

    def states(self, *, settle: bool = False) -> list[JointState]:
        """Every joint's state, read in joint order (as ``[j.state() for j in joints]``; the wheels of a
        ZLAC8015D as ``rig.read_states``: one read of their drive). ``settle``: the caller's next access to the
        world is one that runs its booked time (``World.sync``: the env reads the physics right after), so a
        ZLAC read's one-call exchange may run the reply's travel in its call - the same substeps, counted the
        same, one call fewer."""
        if self._batch is not None:
            got = _states_batch(self._batch)
            if got is not None:
                return got
        out: list[Any] = [None] * len(self._joints)
        for idx, s in self._units:
            for i, state in zip(idx, s.states(settle) if isinstance(s, _ZlacModbus) else s.states()):
                out[i] = state
        return out

    def __repr__(self) -> str:
        names: list[Any] = [j.name for j in self._joints]
        return f"CompiledPath({names})"


def _rig_units(path: CompiledPath) -> list[_ErobModbus] | None:
    """The eRobs of a rig's compiled path whose every request goes in their one-call exchange (one eRob, or
    several on one line and world: :func:`_erob_batch`), in joint order; None: another kind of rig."""
    if path._batch is not None:
        return path._batch
    steppers = path._steppers
    if len(steppers) == 1 and isinstance(steppers[0], _ErobModbus) and steppers[0].exchange is not None:
        return [steppers[0]]
    return None


def _lane_ready(lane: LinkLane, requests: Sequence[Any]) -> bool:
    """What :meth:`LinkLane.exchange` checks before it hands ``requests`` to a one-call exchange with its stock
    reply check (idle, the check the stock one, every request plain and encodable): False where the rig's own way
    must decide (nothing sent either way)."""
    try:
        return lane.framing is not None and lane._stock() and lane.ready(requests)
    except EncodeError:  # the rig's own way raises it, in its turn
        return False


class CompiledRigs:
    """The compiled paths of several rigs (a batch of single envs in one process) whose every joint is an eRob on
    its twin's one-call exchange, in compiled worlds: a whole env step of ALL rigs in one compiled call
    (:meth:`step`: commands, waits, reads), or a step's commands of all rigs in one call and their state reads in
    another (:meth:`command`, :meth:`states`; :meth:`~joints.sim.erob_exchange.ErobExchange.carry_rigs`).

    Rule: each rig gets what its own :meth:`CompiledPath.step` / :meth:`CompiledPath.command` /
    :meth:`CompiledPath.states` gives it - the same checks (each joint's :meth:`_ErobModbus.plan`), requests,
    frames, physics, counts, bookkeeping and states. It is taken only where EVERY rig's every joint is the steady
    case (checked before anything is sent); otherwise :meth:`step` / :meth:`command` / :meth:`states` return None /
    False / None, nothing sent, and each rig goes its own way (its errors raised in its order). :attr:`taken`
    counts the calls it made, :attr:`steps_taken` those that were whole steps."""

    def __init__(self, paths: Sequence[CompiledPath], units: Sequence[list[_ErobModbus]]) -> None:
        self.paths = list(paths)
        self._units = [list(u) for u in units]
        self._lanes = [u[0].lane for u in self._units]
        self._carry = self._units[0][0].exchange.carry_rigs
        self._reads = [[s.status for s in u] for u in self._units]
        self._read_exchanges = [[s.exchange for s in u] for u in self._units]
        self._buffers: dict[tuple[int, int], Any] = {}
        self._worlds = [u[0].exchange.world for u in self._units]
        self.taken = 0  #: compiled calls across the rigs (one per batch command, state read or whole step)
        self.steps_taken = 0  #: of them, whole env steps (:meth:`step`)

    def joined(self) -> bool:
        """Whether every rig's world is in one stepping group (so one call carries them all) and books its sleeps
        (``World.hold_sleeps``, as a single env's: :func:`_hold_sleeps`): then each rig's own sleep books its
        period and the batch's state read runs it, each world's substeps in the one call."""
        worlds = self._worlds
        group = worlds[0].group
        for w in worlds:
            if w.group is not group or not w.hold_sleeps:
                return False
        return True

    @classmethod
    def build(cls, paths: Sequence[CompiledPath | None]) -> CompiledRigs | None:
        """The rigs of ``paths`` in one call, or None where one is not a rig of eRobs on one-call exchanges of one
        kind in a compiled world."""
        units: list[list[_ErobModbus]] = []
        kind: Any = None
        for p in paths:
            u = None if p is None else _rig_units(p)
            if u is None:
                return None
            for s in u:
                if not callable(getattr(s.exchange, "carry_rigs", None)) or (kind is not None
                                                                            and type(s.exchange) is not kind):
                    return None
                if not getattr(s.exchange.world, "compiled", False):  # (the call runs compiled worlds only)
                    return None
                kind = type(s.exchange)
            units.append(u)
        if not units or len({id(u[0].exchange.world) for u in units}) != len(units) \
                or len({id(u[0].exchange.line) for u in units}) != len(units):  # each rig its own world and line
            return None
        return cls(paths, units)  # type: ignore[arg-type]

    def _send(self, requests: list[list[Any]], exchanges: list[list[Any]], lanes: list[LinkLane],
              lazy: bool, holds: list[tuple[int, float]] | None = None) -> list[list[Any]] | None:
        """Each rig's ``requests`` over its lane (``lanes[r]``) in one call (``holds``: each rig's wait for its
        tick among them), counted as the lane counts them; None (nothing sent) where a rig's lane or exchange is
        not the steady case."""
        for lane, reqs in zip(lanes, requests):
            if not _lane_ready(lane, reqs):
                return None
        links = sorted({id(lane.link): lane.link._lock for lane in lanes}.values(), key=id)
        held = 0
        try:
            for lock in links:
                lock.acquire()
                held += 1
            replies: list[list[Any]] | None = self._carry(
                requests, exchanges, [lane.framing.size for lane in lanes],  # type: ignore[union-attr]
                [lane._stock_check for lane in lanes], lazy, self._buffers, holds)
            if replies is None:
                return None
            for lane, reqs in zip(lanes, requests):  # as LinkLane.exchange with its stock check
                lane.count_fused(len(reqs), plain=True)
        finally:
            for lock in reversed(links[:held]):
                lock.release()
        self.taken += 1
        return replies

    def command(self, mode: str, values: Sequence[Sequence[float]], skips: Sequence[Sequence[bool]]) -> bool:
        """Rig ``r``'s :meth:`CompiledPath.command` ``(mode, values[r], skips[r])`` for every rig, in one call;
        False (nothing sent) where a rig's joint is not the steady case or its checks refuse the command (then
        each rig's own command sends it, or raises, in its turn)."""
        if mode not in ACTION_MODES:
            return False
        plans: list[_Planned] = []
        requests: list[list[Any]] = []
        exchanges: list[list[Any]] = []
        lanes: list[LinkLane] = []
        for units, row, skip in zip(self._units, values, skips):
            got = _plan_all(units, mode, row, skip)
            if got is None:
                return False
            planned, reqs, exs = got
            if planned:
                plans.append(planned)
                requests.append(reqs)
                exchanges.append(exs)
                lanes.append(units[0].lane)
        if not requests:
            return True
        befores = [p[0][0].clock.now() for p in plans]
        replies = self._send(requests, exchanges, lanes, False)
        if replies is None:
            return False
        for planned, exs, before in zip(plans, exchanges, befores):  # as _command_batch's bookkeeping
            _note_done(mode, planned, exs[0].clocks, before)
        return True

    def step(self, mode: str, values: Sequence[Sequence[float]], ticks: Sequence[float], rigs: Sequence[Any]
             ) -> list[tuple[list[JointState], float]] | None:
        """Rig ``r``'s :meth:`CompiledPath.step` ``(mode, values[r], None, ticks[r], rigs[r])`` for every rig, in
        ONE call: each rig's commands, its wait for its tick and its state reads, as its own one-call step does
        them (the same frames, substeps and bits); None (nothing sent) where a rig is not that step's steady case
        (a joint not steady or refusing, a sleep that is not its world's hold alone) - then :meth:`command`, the
        waits and :meth:`states`, one after the other."""
        if mode not in ACTION_MODES:
            return None
        plans: list[_Planned] = []
        requests: list[list[Any]] = []
        exchanges: list[list[Any]] = []
        holds: list[tuple[int, float]] = []
        for units, row, tick, rig, reads, readers in zip(self._units, values, ticks, rigs, self._reads,
                                                         self._read_exchanges):
            world = units[0].exchange.world  # (as CompiledPath.step: the rig's sleep is its world's hold alone)
            if rig.clock is not world.clock or not world.hold_sleeps or not rig.sleeps_quietly(tick):
                return None
            got = _plan_all(units, mode, row)
            if got is None:
                return None
            planned, reqs, exs = got
            holds.append((len(reqs), tick))
            plans.append(planned)
            requests.append(reqs + reads)
            exchanges.append(exs + readers)
        befores = [u[0].clock.now() for u in self._units]
        replies = self._send(requests, exchanges, self._lanes, True, holds)
        if replies is None:
            return None
        out: list[tuple[list[JointState], float]] = []
        for units, planned, rig_replies, before, (n, _) in zip(self._units, plans, replies, befores, holds):
            exchange = units[0].exchange  # as _step_batch's bookkeeping
            clocks = exchange.clocks
            _note_done(mode, planned, clocks, before)
            remaining, held = exchange.held
            out.append((_states_read(units, rig_replies[n:], clocks[n:], held), remaining))
        for path in self.paths:
            path.steps_taken += 1
        self.steps_taken += 1
        return out

    def states(self) -> list[list[JointState]] | None:
        """Every rig's :meth:`CompiledPath.states` in one call; None (nothing sent) where a rig is not the steady
        case."""
        units_of = self._units
        befores = [u[0].clock.now() for u in units_of]
        replies = self._send(self._reads, self._read_exchanges, self._lanes, True)
        if replies is None:
            return None
        out: list[list[JointState]] = []
        for units, got, before in zip(units_of, replies, befores):
            if len(units) == 1:  # as _ErobModbus.state: stamped with the clock after the call
                s = units[0]
                out.append([s.state_of(got[0], before, s.clock.now())])
                continue
            out.append(_states_read(units, got, units[0].exchange.clocks, before))  # as _states_batch
        return out
