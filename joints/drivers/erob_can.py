"""ZeroErr eRob over the CAN custom protocol (eRunner manual v1.7, chapters 4 and 7): parameters by index.

Rule: the procedures are :class:`~joints.drivers.erob.ErobDriver`'s, by parameter name; this
module adds what is the CAN custom protocol's own. Parameters travel as indexes/subindexes of
:data:`~joints.devices.erob.can.EROB_CAN` (one value per request: the protocol has no block
transfer), values converted by its ``to_wire``/``from_wire`` (ms over CAN where Modbus counts
0.05 ms), commands of 7.5.2 as commands with or without their parameter. Same ``Joint`` API and
units as the Modbus eRob.

Where the protocol differs from Modbus (each choice cites the manual):

* Speed and torque set-points are the analog value 0x01FE (``analog_quantity_value``) with the
  analog type 0x01FD = 0 "internal" (4.2, 4.3, 7.4.4, 7.4.5); a stop in those modes writes 0 (4.2
  step 5), then the stop command 0x0084.
* Enable/disable is command 0x0100 with its parameter 1/0 (7.5.2); the drive acknowledges it
  several times (chapter 4 figures); the link keeps those acknowledgements from answering later
  requests (:mod:`joints.link.erob_can`).
* There is no "clear errors" command (7.5.2): the error table of appendix 1 (#4) says to disable,
  fix the cause and enable again. :meth:`ErobCanDriver.clear_errors` disables (the drive drops a
  latched error then and reports it again if its cause persists), :meth:`enable` follows.
* There is no emergency-stop command: :meth:`ErobCanDriver.emergency_stop` zeroes the set-point
  and stops with a deceleration that halts the fastest speed within :data:`ESTOP_TIME` (the
  Modbus e-stop's 50 ms).
* Module information (index 0x0232) exists only from firmware X5061715X (note under 7.5.1):
  :meth:`ErobCanDriver.module_info` reads the firmware version first and raises a clear
  :class:`~joints.errors.CommandError` ("not supported") for older firmware, or when the drive
  answers 0x0232 with a failure.
* Persistent or dangerous commands need ``confirm=True`` and send nothing without it: save
  (0x00E8), brake release (0x014F: a loaded joint falls), load-side encoder reset (0x0114 = 1:
  the multi-turn count is lost) and a node id change (0x0043; the bit rate 0x0044 is read-only).
* There is no position offset over CAN, so zero calibration is refused (do it over Modbus RTU).
* Status: every value is one request/reply pair (about 180-200 us at 1 Mbit/s), so
  :meth:`ErobCanDriver.state` reads six values each time and the power-stage temperature (which
  moves on a time constant of minutes) at most every :data:`TEMPERATURE_PERIOD` seconds.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

from joints.clock import Clock
from joints.codecs import erob_can as ec
from joints.devices.erob.can import EROB_CAN, CanMap, ModuleInfo, Reach, module_info_supported
from joints.devices.erob.profiles import ErobProfile
from joints.devices.erob.registers import COUNTS_PER_REV, OperationMode
from joints.drivers.access import ParamAccess
from joints.drivers.base import RawState, sampled_at
from joints.drivers.erob import CalibrationResult, ErobDriver
from joints.errors import CommandError, ConfirmationRequired, DeviceRejected, RegisterError

__all__ = ["CAN_STATUS_NAMES", "ESTOP_TIME", "TEMPERATURE_PERIOD", "ErobCanAccess", "ErobCanDriver"]

#: what :meth:`ErobCanDriver.state` reads every time (one request each)
CAN_STATUS_NAMES = ("error_code", "motion_status", "status_of_achieving_position", "actual_position",
                    "current_speed", "motor_current")
TEMPERATURE = "part_of_power_temperature"
#: s between two reads of the power-stage temperature in :meth:`ErobCanDriver.state`
TEMPERATURE_PERIOD = 1.0
#: s in which :meth:`ErobCanDriver.emergency_stop` halts the drive's fastest speed (Modbus e-stop: < 50 ms)
ESTOP_TIME = 0.05
#: the module-information parameters (index 0x0232) and the versions (0x0001/3, /4)
_MODULE_NAMES = ModuleInfo.NAMES
_WHERE = re.compile(r"(0x[0-9a-fA-F]+|\d+)(?:[/:](0x[0-9a-fA-F]+|\d+))?")


class ErobCanAccess(ParamAccess):
    """Parameters of one eRob node over the CAN custom protocol (one value per request)."""

    protocol = "erob-can"

    def __init__(self, link: Any, node: int, cmap: CanMap = EROB_CAN) -> None:
        if type(node) is not int or not ec.NODE_MIN <= node <= ec.NODE_MAX:
            raise CommandError(f"eRob CAN node id must be {ec.NODE_MIN}..{ec.NODE_MAX}, got {node!r}")
        self.link = link
        self.node = node
        self.map = cmap
        self.params = cmap.params

    def resolve(self, key: str | int) -> str:
        if isinstance(key, int):
            return self._at(key, None)
        if key in self.map:
            return key
        m = _WHERE.fullmatch(key.strip())
        if m is not None:  # "0x0005/1", "0x0232:2", "2"
            return self._at(int(m.group(1), 0), None if m.group(2) is None else int(m.group(2), 0))
        self.map.key(key)  # raises the right RegisterError (unknown, or not reachable over CAN)
        return key

    def _at(self, index: int, subindex: int | None) -> str:
        try:
            return self.map.at(index, subindex)
        except RegisterError:
            if subindex is None:
                subs = sorted(k.subindex for k in self.map.keys.values() if k.index == index and k.subindex is not None)
                if len(subs) == 1:
                    return self.map.at(index, subs[0])
                if subs:
                    raise RegisterError(f"eRob CAN: index 0x{index:04X} has subindexes {subs}; name one, "
                                        f"e.g. 0x{index:04X}/{subs[0]}") from None
            raise

    def where(self, name: str) -> str:
        return str(self.map.key(name))

    def read(self, name: str) -> int:
        key = self.map.key(name)
        if key.reach is not Reach.VALUE or not self.map.access(name).readable:
            raise RegisterError(f"eRob CAN: {name} ({key}) is a command and cannot be read; nothing was sent")
        reply = self.link.request(ec.Read(self.node, key.index, key.subindex), idempotent=True)
        return self.map.from_wire(name, reply.value)

    def read_many(self, names: Sequence[str]) -> dict[str, int]:
        return {n: self.read(n) for n in dict.fromkeys(names)}

    def message(self, name: str, value: int) -> ec.Request:
        """The request that writes ``value`` to ``name`` (checked; raises before anything is sent)."""
        key = self.map.key(name)
        if not self.map.access(name).writable:
            raise RegisterError(f"eRob CAN: {name} ({key}) is read-only over CAN; nothing was sent")
        if key.reach is Reach.COMMAND:
            self.params[name].check(value)
            return ec.Command(self.node, key.index)
        wire = self.map.to_wire(name, value)
        if key.reach is Reach.COMMAND_WITH_PARAMETER:
            return ec.Command(self.node, key.index, wire)
        return ec.Write(self.node, key.index, wire, key.subindex)

    def write(self, name: str, value: int, *, idempotent: bool = True) -> None:
        msg = self.message(name, value)
        self.link.request(msg, idempotent=idempotent and not isinstance(msg, ec.Command))

    def write_many(self, values: Mapping[str, int], *, idempotent: bool = True) -> None:
        messages = [self.message(n, v) for n, v in values.items()]  # every value checked first
        for msg in messages:
            self.link.request(msg, idempotent=idempotent and not isinstance(msg, ec.Command))


class ErobCanDriver(ErobDriver):
    """One eRob actuator on an eRob CAN custom-protocol link (see the module docstring)."""

    start_check_names = ("motion_status", "status_of_achieving_position")
    #: what :meth:`set_velocity` and :meth:`set_current` write before their set-point (besides the ramps): the
    #: steady checks (``steady_velocity``, ``steady_current``) ask that the drive holds them
    _SPEED_SETUP = (*ErobDriver._SPEED_SETUP, ("analog_quantity_type", 0))
    _TORQUE_SETUP = (*ErobDriver._TORQUE_SETUP, ("analog_quantity_type", 0))

    def __init__(
        self,
        link: Any,
        node: int,
        *,
        profile: ErobProfile | str | None = None,
        clock: Clock | None = None,
        name: str = "",
    ) -> None:
        self.link = link
        self.node = node
        super().__init__(ErobCanAccess(link, node), profile=profile, clock=clock or link.clock,
                         name=name or f"erob@can:{node}")
        self._temperature: tuple[float, int] | None = None  # (time read, value)

    # -- set-points: the analog value 0x01FE ----------------------------------------------------
    def _analog(self, value: int) -> None:
        self._set("analog_quantity_type", 0)  # 0 = internal: the set-point comes over the bus (7.4.4 step 3)
        self._settle_after_enable()
        self._set("analog_quantity_value", value, force=True)

    def configure_velocity(self, *, acceleration: int | None = None, deceleration: int | None = None) -> None:
        """Steps before "enable" in 7.4.4: speed mode, control source, analog type, ramps, set-point 0."""
        self._operation_mode(OperationMode.SPEED)
        self._set("control_source", 0)
        self._set("analog_quantity_type", 0)
        self._set_many(self._profile(None, acceleration, deceleration))
        self._set("analog_quantity_value", 0, force=True)

    def configure_torque(self, *, max_speed: int | None = None) -> None:
        """Steps before "enable" in 7.4.5: torque mode, control source, analog type, speed limit, set-point 0."""
        self._operation_mode(OperationMode.TORQUE)
        self._set("control_source", 0)
        self._set("analog_quantity_type", 0)
        if max_speed is not None:
            self.set_torque_speed_limit(max_speed)
        self._set("analog_quantity_value", 0, force=True)

    def set_velocity(self, velocity: int, *, acceleration: int | None = None, deceleration: int | None = None) -> None:
        """Speed control (7.4.4): mode 2, ramps, analog value = target speed [count/s]."""
        self._validate(analog_quantity_value=velocity, target_speed=velocity, profile_acceleration=acceleration,
                       profile_deceleration=deceleration)
        self._operation_mode(OperationMode.SPEED)
        self._set("control_source", 0)
        self._set_many(self._profile(None, acceleration, deceleration))
        self._analog(velocity)

    def set_current(self, current: int) -> None:
        """Torque control (7.4.5): mode 1, analog value = target current [mA]."""
        self._validate(analog_quantity_value=current, target_current=current)
        self._operation_mode(OperationMode.TORQUE)
        self._set("control_source", 0)
        self._analog(current)

    def stop_repetitive(self) -> None:
        """Refused: 7.5.2 has no stop-repetitive command (Modbus 0x00F4); stop() ends a repetitive move."""
        raise CommandError(f"{self.name}: the CAN custom protocol has no 'stop repetitive motion' command "
                           "(eRunner 7.5.2); use stop(); nothing was sent")

    # -- stopping ------------------------------------------------------------------------------
    def _zero_setpoint(self) -> None:
        if self._cache.get("operation_mode") in (OperationMode.SPEED, OperationMode.TORQUE):
            self._set("analog_quantity_value", 0, force=True)

    def stop(self) -> None:
        """Speed/torque: analog value 0 (4.2 step 5); then Stop (0x0084): decelerate with the profile deceleration."""
        self._zero_setpoint()
        self._command("stop_operating", 0)

    def emergency_stop(self) -> None:
        """No e-stop command over CAN: set-point 0, deceleration to halt within ESTOP_TIME, Stop (0x0084)."""
        top = math.ceil(self.profile.max_speed * COUNTS_PER_REV / (2.0 * math.pi) / ESTOP_TIME)
        self._zero_setpoint()
        self._set("profile_deceleration", max(top, self._cache.get("profile_deceleration", 0)))
        self._command("stop_operating", 0)

    def clear_errors(self) -> None:
        """No clear command over CAN (7.5.2; appendix 1 #4: disable, fix, enable): disables the motor.

        The brake engages and the drive drops its latched error; an error whose cause persists is
        reported again at once. Then :meth:`enable` again.
        """
        self.disable()

    def motion_targets(self) -> dict[str, tuple[str, float]]:
        """Motion set-points over CAN: the analog value is a speed or a current by operation mode."""
        rad = self.units.position
        analog = (("current", 0.001) if self._cache.get("operation_mode") == OperationMode.TORQUE
                  else ("velocity", rad))
        return {"target_absolute_position": ("position", rad), "target_relative_position": ("relative", rad),
                "profile_speed": ("velocity", rad), "torque_control_mode_max_speed": ("velocity", rad),
                "analog_quantity_value": analog}

    # -- status --------------------------------------------------------------------------------
    def state(self) -> RawState:
        """Six reads (status, position, speed, current); the temperature at most every TEMPERATURE_PERIOD."""
        t0 = self.clock.now()
        return self.state_read(self.access.read_many(self.state_names(t0)), t0, self.clock.now())

    def state_names(self, t0: float) -> tuple[str, ...]:
        """What :meth:`state` reads when it starts at ``t0``: :data:`CAN_STATUS_NAMES`, and the temperature when
        its last read is :data:`TEMPERATURE_PERIOD` old."""
        cached = self._temperature
        if cached is None or t0 - cached[0] >= TEMPERATURE_PERIOD or t0 < cached[0]:
            return (*CAN_STATUS_NAMES, TEMPERATURE)
        return CAN_STATUS_NAMES

    def state_read(self, v: dict[str, int], t0: float, t1: float) -> RawState:
        """The state from the values ``v`` of :meth:`state_names` read between the clock instants ``t0`` and ``t1``
        (the temperature kept, or the kept one filled in)."""
        cached = self._temperature
        if TEMPERATURE in v:
            self._temperature = (t0, v[TEMPERATURE])
        else:
            assert cached is not None
            v[TEMPERATURE] = cached[1]
        return self.state_from(v, sampled_at(t0, t1))

    def forget(self) -> None:
        super().forget()
        self._temperature = None

    def compiled_step(self, joint: Any) -> Any:
        """The sim's compiled path's step of ``joint`` (this driver's) where its link's peer is an in-process twin
        that offers a one-call exchange (:mod:`joints.drivers.erob_can_steady`), else None."""
        return erob_can_steady.stepper(joint)

    # -- module information (7.5.3) ------------------------------------------------------------
    def versions(self) -> tuple[int, int]:
        """(hardware version 0x0001/3, firmware version 0x0001/4), as the drive reports them."""
        return self.read("hardware_version"), self.read("firmware_version")

    def module_info(self, versions: tuple[int, int] | None = None) -> ModuleInfo:
        """Serial number, model string and versions (7.5.3); CommandError where the firmware lacks 0x0232.

        ``versions``: (hardware, firmware) already read (else they are read first).
        """
        hardware, firmware = versions or self.versions()
        if module_info_supported(firmware) is False:
            raise CommandError(f"{self.name}: module information (index 0x0232) is not supported by firmware "
                               f"{firmware}; it needs X5061715X or later (eRunner 7.5.1); nothing was asked")
        values = {"hardware_version": hardware, "firmware_version": firmware}
        try:
            for name in _MODULE_NAMES[:6]:
                values[name] = self.read(name)
        except DeviceRejected as exc:
            raise CommandError(f"{self.name}: module information (index 0x0232) is not supported by this drive "
                               f"(firmware {firmware}): {exc}") from exc
        return ModuleInfo.from_values(values)

    def identity(self) -> dict[str, object]:
        """Model, serial number and versions as eRunner shows them (7.5.3); versions only on older firmware."""
        versions = self.versions()
        out: dict[str, object] = {"hardware_version": str(versions[0]), "firmware_version": versions[1]}
        try:
            info = self.module_info(versions)
        except CommandError as exc:
            out["module_info"] = f"not supported: {exc}"
            return out
        out.update(model=info.model, serial_number=info.serial_number, hardware_version=info.hardware_version_text,
                   module_version=info.version_text)
        return out

    # -- persistent / dangerous commands (need confirmation) ----------------------------------
    def reset_output_encoder(self, *, confirm: bool = False) -> None:
        """Reset the load-side encoder (0x0114 = 1): clears a multi-turn battery alarm and the multi-turn count."""
        if not confirm:
            raise ConfirmationRequired(
                f"{self.name}: reset_output_encoder (0x0114) clears the multi-turn position; pass confirm=True"
            )
        self._command("reset_output_encoder", 1)

    def release_brake(self, *, confirm: bool = False) -> None:
        """Release the holding brake (0x014F) while the motor is off: a loaded joint falls."""
        if not confirm:
            raise ConfirmationRequired(
                f"{self.name}: release_brake (0x014F) lets the joint move freely - a loaded joint falls; "
                "support the load, then pass confirm=True"
            )
        self._command("release_brake", 0)

    def set_node_id(self, node: int, *, confirm: bool = False) -> None:
        """Write a new CAN node id (0x0043); it takes effect after save_parameters and a power cycle."""
        self.params["can_address"].check(node)
        if not confirm:
            raise ConfirmationRequired(
                f"{self.name}: set_node_id moves the drive to node {node} (after saving and a power cycle); "
                "pass confirm=True"
            )
        self.write_param("can_address", node)

    def calibrate_zero(self, *, multi_turn: bool = False, save: bool = True,
                       confirm: bool = False) -> CalibrationResult:
        """Refused: the CAN custom protocol has no position offset (7.5.1); calibrate over Modbus RTU."""
        raise CommandError(f"{self.name}: zero calibration needs the position offset, which the CAN custom "
                           "protocol does not reach (eRunner 7.5.1); use Modbus RTU; nothing was sent")


# (imported last: it builds on this module; its check of the stock methods is captured when this module loads)
from joints.drivers import erob_can_steady
