"""eRob error codes (register 0x0060 ``error_code``) with the manuals' text.

Rule: pure data. The Modbus manual documents one code itself (0xFA2 = 4002, RS485 communication
timeout) and refers to the eRob user manual's appendix for the rest, which is not in our manual
set. The eRunner manual's appendix 1 lists the command-rejection codes of the same firmware; they
are included because a Modbus drive reports the same conditions (e.g. start while disabled).
Every code has a short ``name`` (the :class:`~joints.devices.faults.Fault` it becomes).
"""

from __future__ import annotations

from dataclasses import dataclass

from joints.devices.faults import Fault


@dataclass(frozen=True, slots=True)
class FaultInfo:
    code: int
    text: str
    hint: str
    source: str
    name: str = "drive_error"

    def fault(self) -> Fault:
        return Fault(self.code, self.name, self.text, self.hint, self.source)


_FAULTS = (
    FaultInfo(
        0x0FA2,
        "RS485 communication timeout",
        "no frame arrived within modbus_communication_timeout_duration (0x0002); "
        "clear errors, then poll faster or raise the timeout",
        "Modbus manual v1.6, register 0x0002",
        name='rs485_timeout',
    ),
    FaultInfo(0x0015, "parameter write or command invalid while the motor is moving",
              "stop the motion before changing this parameter", "eRunner v1.7 appendix 1 #1", name='busy_moving'),
    FaultInfo(0x0016, "parameter write or command invalid while the motor is enabled",
              "disable the motor before changing this parameter", "eRunner v1.7 appendix 1 #2", name='busy_enabled'),
    FaultInfo(0x001F, "commutation not finished after power-on; cannot enable",
              "wait at least 8 s after power-on before commanding", "eRunner v1.7 appendix 1 #3", name='commutation_pending'),
    FaultInfo(0x0027, "cannot start motion while the motor is off",
              "enable the motor first, then start; if the error follows enable, clear the fault "
              "and enable again", "eRunner v1.7 appendix 1 #4", name='start_while_disabled'),
    FaultInfo(0x0030, "start with an invalid motion mode value",
              "set motion_mode (0x0041) to 0, 1 or 2", "eRunner v1.7 appendix 1 #5", name='invalid_motion_mode'),
    FaultInfo(0x0032, "this command needs a parameter",
              "send the command with its 4-byte parameter (eRunner 7.3, table 7-10)", "eRunner v1.7 appendix 1 #6", name='command_needs_parameter'),
    FaultInfo(0x0033, "this command takes no parameter",
              "send the command without a parameter (eRunner 7.3, table 7-9)", "eRunner v1.7 appendix 1 #7", name='command_takes_no_parameter'),
    FaultInfo(0x0056, "cannot enable: relay not active",
              "wait at least 8 s after power-on before commanding", "eRunner v1.7 appendix 1 #8", name='relay_not_active'),
    FaultInfo(0x014A, "brake control not configured",
              "configure the brake type in eTuner", "eRunner v1.7 appendix 1 #9", name="brake_not_configured"),
    # The protection faults below are not numbered in our manual set; the emulator reports them with
    # the CiA 402 error codes (the eRob's CANopen profile), so a real drive may use other numbers.
    FaultInfo(0x8611, "position following error above max_position_error (0x00B9)",
              "check load, gains and profile acceleration; clear errors and enable again", "CiA 402 (emulator)", name='following_error'),
    FaultInfo(0x8400, "speed error above max_speed_error (0x00BB)",
              "reduce acceleration or load; clear errors and enable again", "CiA 402 (emulator)", name='speed_error'),
    FaultInfo(0x7121, "motor stalled (struck current/speed/time, 0x00C5-0x00C9)",
              "remove the blockage; clear errors and enable again", "CiA 402 (emulator)", name='stall'),
    FaultInfo(0x8612, "position outside min/max position limit (0x00BD/0x00BF)",
              "move back inside the limits", "CiA 402 (emulator)", name='position_limit'),
    FaultInfo(0x4310, "power stage above power_temperature_protection_value (0x00D1)",
              "let the drive cool down, reduce the duty", "CiA 402 (emulator)", name='over_temperature'),
)

FAULTS: dict[int, FaultInfo] = {f.code: f for f in _FAULTS}

#: The communication-watchdog fault code (0xFA2).
RS485_TIMEOUT = 0x0FA2
#: Start while the motor is off.
START_WHILE_DISABLED = 0x0027


def describe(code: int) -> FaultInfo:
    """Text for an error code; unknown codes get a pointer to the vendor's table."""
    info = FAULTS.get(code)
    if info is not None:
        return info
    return FaultInfo(
        code,
        "drive error (code not documented in the Modbus/eRunner manuals)",
        "look it up in the eRob user manual, appendix 'error codes', then clear errors",
        "-",
        "undocumented_error",
    )


def fault(code: int) -> Fault | None:
    """The :class:`Fault` of an error code register value (None for 0 = no error)."""
    return describe(code).fault() if code else None
