"""The compiled path: an env step's commands and state reads for in-process twins, in one call each.

Rule: the driver path (:class:`~joints.joint.Joint` -> driver -> parameter access -> link) is the
reference and the only path to hardware; this path changes which Python runs, never what happens.
It is built only for joints whose link hands requests to an in-process twin as objects (the sim's
direct path, :class:`~joints.link.base.DirectFraming`) and whose driver family it knows (eRob over
Modbus RTU). For each joint it keeps, per step:

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
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from joints.codecs import modbus as mb
from joints.drivers.access import ModbusAccess
from joints.drivers.base import sampled_at
from joints.drivers.erob import CMD_START, STATUS_NAMES
from joints.drivers.erob_modbus import ErobModbusDriver
from joints.errors import OutcomeUnknown
from joints.joint import Joint, JointState
from joints.link.base import DirectFraming

__all__ = ["CompiledPath", "supported"]

ACTION_MODES = ("position", "velocity", "torque")


class _ErobModbus:
    """One eRob on a Modbus RTU direct path: target + start, target speed or target current; one FC03 state."""

    def __init__(self, joint: Joint, driver: ErobModbusDriver, access: ModbusAccess) -> None:
        self.joint = joint
        self.driver = driver
        self.access = access
        self.link = access.link
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

    def _write(self, name: str, value: int) -> None:
        self.link.request(self.access.write_request(name, value), idempotent=True)
        self.driver.note_written(name, value)

    def command(self, mode: str, value: float) -> None:
        joint, driver = self.joint, self.driver
        if mode == "position":
            target, speed, acc, dec = joint.position_command(value)
            if driver.steady_move(speed, acc, dec):
                driver.validate(target_absolute_position=target)
                self._write("target_absolute_position", target)
                try:  # a command: never retried
                    self.link.request(self.start, idempotent=False)
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
        reply = self.link.request(self.status, idempotent=True)
        assert isinstance(reply, mb.ReadRegistersReply)
        values = self.decode(self.status_start, reply.values)
        return self.joint.to_si(self.driver.state_from(values, sampled_at(t0, clock.now())))


def _stepper(joint: Joint) -> _ErobModbus | None:
    driver = joint.driver
    if isinstance(driver, ErobModbusDriver):
        access = driver.access
        if isinstance(access, ModbusAccess) and isinstance(access.link.framing, DirectFraming):
            return _ErobModbus(joint, driver, access)
    return None


def supported(joint: Joint) -> bool:
    """Whether the compiled path can step ``joint`` (a known family on an in-process direct path)."""
    return _stepper(joint) is not None


class CompiledPath:
    """The commands and state reads of a list of joints, each joint's in order (see the module docstring)."""

    def __init__(self, joints: Sequence[Joint]) -> None:
        steppers = [_stepper(j) for j in joints]
        missing = [j.name for j, s in zip(joints, steppers) if s is None]
        if missing:
            raise ValueError(f"the compiled path cannot step joints {missing} (not an in-process twin of a "
                             "family it knows); use the driver path")
        self._steppers: list[_ErobModbus] = [s for s in steppers if s is not None]

    @classmethod
    def build(cls, joints: Sequence[Joint]) -> CompiledPath | None:
        """The compiled path of ``joints``, or None where one of them is not :func:`supported`."""
        return cls(joints) if joints and all(supported(j) for j in joints) else None

    @property
    def taken(self) -> int:
        """Joint steps (commands) sent the compiled way, not through the driver's own method."""
        return sum(s.taken for s in self._steppers)

    def command(self, mode: str, values: Sequence[float], skip: Sequence[bool] | None = None) -> None:
        """Joint ``i`` gets ``values[i]`` (rad | rad/s | N*m per ``mode``) unless ``skip[i]``, in joint order."""
        if mode not in ACTION_MODES:
            raise ValueError(f"mode {mode!r} is not one of {ACTION_MODES}")
        for i, (s, v) in enumerate(zip(self._steppers, values)):
            if skip is None or not skip[i]:
                s.command(mode, v)

    def states(self) -> list[JointState]:
        """Every joint's state, read in joint order (as ``[j.state() for j in joints]``)."""
        return [s.state() for s in self._steppers]

    def __repr__(self) -> str:
        names: list[Any] = [s.joint.name for s in self._steppers]
        return f"CompiledPath({names})"
