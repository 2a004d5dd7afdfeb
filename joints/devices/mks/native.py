"""The native MKS RS485 protocol's map over :data:`~joints.devices.mks.params.MKS_PARAMS`.

Rule: pure data. Each parameter is reached by one command code and one field of that command's
message (:mod:`joints.codecs.mks`): the request's field for parameters one writes, the reply's
field for parameters one reads; ``field == ""`` for commands without data. Command names follow
the manual (Parts 5 and 6); :class:`Command` values are the function codes.

Who answers (manual Part 4, 5.2 #13, 5.2 #16, 5.7, 6.5-6.9; :func:`expects_reply`)
    * address 0 (broadcast), a group address (0x8D) and long packets (0xFC): nobody answers;
    * ``slave_respond = 0`` (0x8C) silences the replies to the run commands of Part 6 (0xF4, 0xF5,
      0xF6, 0xFD, 0xFE) and their completion frames; every other command still answers;
    * ``slave_active = 1`` (default) adds a completion frame (status 2 complete / 3 end-limit
      stop) to a run command's immediate reply (0 fail / 1 started) when the motion ends.
    Choices where the manual is silent (:data:`REPLY_RULES`): go home (0x91, "1 start, 2 success")
    follows the run commands (its 2 arrives later when active is on, but 0x8C's note does not name
    it, so respond-off does not silence it); calibrate (0x80, "0 calibrating", later 1/2) and
    save/clean (0xFF, "1 start", later 2) always send their later frame.
"""

from __future__ import annotations

import enum
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from types import MappingProxyType

from joints.devices.mks.params import MKS_PARAMS
from joints.devices.params import ParamMap

__all__ = ["BLOCK_COMMANDS", "BROADCAST", "MKS_NATIVE", "OPTIONAL_FIELDS", "REPLY_RULES", "Command", "NativeKey", "ReplyRule", "expects_completion",
           "expects_reply"]

BROADCAST = 0


class Command(enum.IntEnum):
    """Function codes of Parts 5 and 6 (names after the manual's section titles)."""

    SET_TIMED_RETURN = 0x01
    READ_CONFIGURATION_PARAMETER = 0x00
    READ_ENCODER_VALUE_CARRY = 0x30
    READ_ENCODER_VALUE_ADDITION = 0x31
    READ_REAL_TIME_SPEED = 0x32
    READ_NUMBER_OF_PULSES = 0x33
    READ_IO_PORTS_STATUS = 0x34
    READ_RAW_ENCODER_VALUE = 0x35
    WRITE_IO_PORT = 0x36
    READ_ERROR_OF_ANGLE = 0x39
    READ_EN_PINS_STATUS = 0x3A
    READ_GO_BACK_TO_ZERO_STATUS = 0x3B
    RELEASE_PROTECTION_STATE = 0x3D
    READ_PROTECTION_STATE = 0x3E
    RESTORE_DEFAULT_PARAMETERS = 0x3F
    READ_VERSION_INFORMATION = 0x40
    WRITE_ALL_PARAMETERS = 0x46
    READ_ALL_PARAMETERS = 0x47
    READ_ALL_STATUS = 0x48
    RESTART_MOTOR = 0x41
    USER_ID = 0x42
    SET_SYNC = 0x4A
    IAP_CONTROL = 0x50
    SYNC_EXECUTE = 0x4B
    CALIBRATE_ENCODER = 0x80
    SET_WORK_MODE = 0x82
    SET_WORKING_CURRENT = 0x83
    SET_SUBDIVISION = 0x84
    SET_EN_PIN_ACTIVE = 0x85
    SET_DIRECTION = 0x86
    SET_AUTO_SCREEN_OFF = 0x87
    SET_LOCKED_ROTOR_PROTECTION = 0x88
    SET_SUBDIVISION_INTERPOLATION = 0x89
    SET_BAUD_RATE = 0x8A
    SET_SLAVE_ADDRESS = 0x8B
    SET_RESPOND_ACTIVE = 0x8C
    SET_GROUP_ADDRESS = 0x8D
    SET_MODBUS_RTU = 0x8E
    SET_KEY_LOCK = 0x8F
    SET_HOME_PARAMETERS = 0x90
    GO_HOME = 0x91
    SET_CURRENT_AXIS_TO_ZERO = 0x92
    SET_NOLIMIT_HOME_PARAMETERS = 0x94
    SET_HEARTBEAT_PROTECTION_TIME = 0x98
    SET_ZERO_MODE = 0x9A
    SET_HOLDING_CURRENT = 0x9B
    SET_POSITION_ERROR_PROTECTION = 0x9D
    SET_POSITION_THRESHOLD = 0x95
    SET_VFOC_PID = 0x96
    SET_CLOSE_PID = 0x97
    SET_LIMIT_PORT_REMAP = 0x9E
    SET_PULSE_DIVIDER = 0x99
    SET_IN1_PORT_MODE = 0x9F
    QUERY_MOTOR_STATUS = 0xF1
    ENABLE_MOTOR = 0xF3
    POSITION_MODE3_RELATIVE_AXIS = 0xF4
    POSITION_MODE4_ABSOLUTE_AXIS = 0xF5
    SPEED_MODE = 0xF6
    EMERGENCY_STOP = 0xF7
    POSITION_MODE1_RELATIVE_PULSES = 0xFD
    POSITION_MODE2_ABSOLUTE_PULSES = 0xFE
    SAVE_CLEAN_SPEED_MODE = 0xFF


LONG_PACKET = 0xFC  #: head of a long data package (not a function code)

#: commands that carry no parameter's fields: whole blocks (joints.devices.mks.blocks, V1.0.6), the timed
#: return of another command's reply (0x01, V1.0.9), the read of another command's parameter (0x00, V1.0.8) and the synchronous execution (0x4B, V1.0.8; broadcast)
BLOCK_COMMANDS = frozenset((Command.WRITE_ALL_PARAMETERS, Command.READ_ALL_PARAMETERS, Command.READ_ALL_STATUS,
                            Command.SET_TIMED_RETURN, Command.SYNC_EXECUTE, Command.READ_CONFIGURATION_PARAMETER))

#: fields of a later firmware whose value 0 is the command's older, shorter frame (a drive without the feature
#: takes the command when they are 0)
OPTIONAL_FIELDS = frozenset(("speed_mode_run_time", "working_current_unsaved", "go_home_mode"))

#: run commands of Part 6 (0x8C respond/active applies to them)
RUN_COMMANDS = frozenset((Command.SPEED_MODE, Command.POSITION_MODE1_RELATIVE_PULSES,
                          Command.POSITION_MODE2_ABSOLUTE_PULSES, Command.POSITION_MODE3_RELATIVE_AXIS,
                          Command.POSITION_MODE4_ABSOLUTE_AXIS))


@dataclass(frozen=True, slots=True)
class NativeKey:
    """Where a parameter lives in the native protocol: a command and a field of its message."""

    command: Command
    field: str = ""  #: message field ("" = the command itself, no data)

    def __repr__(self) -> str:
        return f"NativeKey(0x{int(self.command):02X} {self.command.name}{'.' + self.field if self.field else ''})"


@dataclass(frozen=True, slots=True)
class ReplyRule:
    """How a command is answered (see the module docstring)."""

    silenced_by_respond_off: bool = False  #: 0x8C respond = 0 suppresses its replies
    completion: bool = False  #: a later frame with the same code ends it
    completion_needs_active: bool = False  #: ... only when 0x8C active = 1


_RUN = ReplyRule(silenced_by_respond_off=True, completion=True, completion_needs_active=True)
REPLY_RULES: Mapping[Command, ReplyRule] = MappingProxyType({
    **{c: ReplyRule() for c in Command},
    **{c: _RUN for c in RUN_COMMANDS},
    Command.GO_HOME: ReplyRule(completion=True, completion_needs_active=True),
    Command.CALIBRATE_ENCODER: ReplyRule(completion=True),
    Command.SAVE_CLEAN_SPEED_MODE: ReplyRule(completion=True),
})


def expects_reply(command: int, address: int, *, groups: Collection[int] = (), respond: bool = True) -> bool:
    """Does a drive answer ``command`` sent to ``address``? (Not for long packets: never.)"""
    if address == BROADCAST or address in groups:
        return False
    rule = REPLY_RULES.get(Command(command)) if command in _CODES else None
    if rule is None:
        return False  # an unknown code: the manual documents no answer
    return respond or not rule.silenced_by_respond_off


def expects_completion(command: int, address: int, *, groups: Collection[int] = (), respond: bool = True,
                       active: bool = True) -> bool:
    """Does a later completion frame follow the immediate reply? (Only if the reply says started.)"""
    if not expects_reply(command, address, groups=groups, respond=respond):
        return False
    rule = REPLY_RULES[Command(command)]
    return rule.completion and (active or not rule.completion_needs_active)


_CODES = frozenset(int(c) for c in Command)

C = Command
_KEYS: dict[str, NativeKey] = {
    "encoder_carry": NativeKey(C.READ_ENCODER_VALUE_CARRY, "carry"),
    "encoder_value": NativeKey(C.READ_ENCODER_VALUE_CARRY, "value"),
    "encoder_addition": NativeKey(C.READ_ENCODER_VALUE_ADDITION, "value"),
    "real_time_speed": NativeKey(C.READ_REAL_TIME_SPEED, "speed"),
    "number_of_pulses": NativeKey(C.READ_NUMBER_OF_PULSES, "pulses"),
    "io_status": NativeKey(C.READ_IO_PORTS_STATUS, "status"),
    "angle_error": NativeKey(C.READ_ERROR_OF_ANGLE, "error"),
    "en_pin_status": NativeKey(C.READ_EN_PINS_STATUS, "enabled"),
    "go_back_to_zero_status": NativeKey(C.READ_GO_BACK_TO_ZERO_STATUS, "status"),
    "homing_status": NativeKey(C.READ_GO_BACK_TO_ZERO_STATUS, "homing"),
    "protection_state": NativeKey(C.READ_PROTECTION_STATE, "protected"),
    "motor_status": NativeKey(C.QUERY_MOTOR_STATUS, "status"),
    "release_protection": NativeKey(C.RELEASE_PROTECTION_STATE),
    "restore_default_parameters": NativeKey(C.RESTORE_DEFAULT_PARAMETERS),
    "restart_motor": NativeKey(C.RESTART_MOTOR),
    "calibrate": NativeKey(C.CALIBRATE_ENCODER),
    "go_home": NativeKey(C.GO_HOME),
    "go_home_mode": NativeKey(C.GO_HOME, "mode"),
    "set_current_axis_to_zero": NativeKey(C.SET_CURRENT_AXIS_TO_ZERO),
    "emergency_stop": NativeKey(C.EMERGENCY_STOP),
    "work_mode": NativeKey(C.SET_WORK_MODE, "mode"),
    "working_current": NativeKey(C.SET_WORKING_CURRENT, "current"),
    "working_current_unsaved": NativeKey(C.SET_WORKING_CURRENT, "unsaved"),
    "holding_current": NativeKey(C.SET_HOLDING_CURRENT, "hold"),
    "microsteps": NativeKey(C.SET_SUBDIVISION, "microsteps"),
    "en_active_level": NativeKey(C.SET_EN_PIN_ACTIVE, "level"),
    "motor_direction": NativeKey(C.SET_DIRECTION, "direction"),
    "auto_screen_off": NativeKey(C.SET_AUTO_SCREEN_OFF, "enable"),
    "locked_rotor_protection": NativeKey(C.SET_LOCKED_ROTOR_PROTECTION, "enable"),
    "subdivision_interpolation": NativeKey(C.SET_SUBDIVISION_INTERPOLATION, "enable"),
    "baud_rate": NativeKey(C.SET_BAUD_RATE, "baud"),
    "slave_address": NativeKey(C.SET_SLAVE_ADDRESS, "new_address"),
    "slave_respond": NativeKey(C.SET_RESPOND_ACTIVE, "respond"),
    "slave_active": NativeKey(C.SET_RESPOND_ACTIVE, "active"),
    "group_address": NativeKey(C.SET_GROUP_ADDRESS, "group"),
    "modbus_rtu": NativeKey(C.SET_MODBUS_RTU, "enable"),
    "key_lock": NativeKey(C.SET_KEY_LOCK, "lock"),
    "home_trigger_level": NativeKey(C.SET_HOME_PARAMETERS, "trigger_level"),
    "home_direction": NativeKey(C.SET_HOME_PARAMETERS, "direction"),
    "home_speed": NativeKey(C.SET_HOME_PARAMETERS, "speed"),
    "end_limit": NativeKey(C.SET_HOME_PARAMETERS, "end_limit"),
    "home_reverse_angle": NativeKey(C.SET_NOLIMIT_HOME_PARAMETERS, "reverse_angle"),
    "home_mode": NativeKey(C.SET_NOLIMIT_HOME_PARAMETERS, "mode"),
    "home_current": NativeKey(C.SET_NOLIMIT_HOME_PARAMETERS, "current"),
    "limit_port_remap": NativeKey(C.SET_LIMIT_PORT_REMAP, "enable"),
    "zero_mode": NativeKey(C.SET_ZERO_MODE, "mode"),
    "zero_mode_set_zero": NativeKey(C.SET_ZERO_MODE, "set_zero"),
    "zero_mode_speed": NativeKey(C.SET_ZERO_MODE, "speed"),
    "zero_mode_direction": NativeKey(C.SET_ZERO_MODE, "direction"),
    "motor_enable": NativeKey(C.ENABLE_MOTOR, "enable"),
    "speed_mode_direction": NativeKey(C.SPEED_MODE, "direction"),
    "speed_mode_speed": NativeKey(C.SPEED_MODE, "speed"),
    "speed_mode_acc": NativeKey(C.SPEED_MODE, "acc"),
    "speed_mode_run_time": NativeKey(C.SPEED_MODE, "run_time"),
    "save_clean_speed_mode_parameter": NativeKey(C.SAVE_CLEAN_SPEED_MODE, "state"),
    "position_mode1_direction": NativeKey(C.POSITION_MODE1_RELATIVE_PULSES, "direction"),
    "position_mode1_speed": NativeKey(C.POSITION_MODE1_RELATIVE_PULSES, "speed"),
    "position_mode1_acc": NativeKey(C.POSITION_MODE1_RELATIVE_PULSES, "acc"),
    "position_mode1_pulses": NativeKey(C.POSITION_MODE1_RELATIVE_PULSES, "pulses"),
    "position_mode2_speed": NativeKey(C.POSITION_MODE2_ABSOLUTE_PULSES, "speed"),
    "position_mode2_acc": NativeKey(C.POSITION_MODE2_ABSOLUTE_PULSES, "acc"),
    "position_mode2_abs_pulses": NativeKey(C.POSITION_MODE2_ABSOLUTE_PULSES, "abs_pulses"),
    "position_mode3_speed": NativeKey(C.POSITION_MODE3_RELATIVE_AXIS, "speed"),
    "position_mode3_acc": NativeKey(C.POSITION_MODE3_RELATIVE_AXIS, "acc"),
    "position_mode3_rel_axis": NativeKey(C.POSITION_MODE3_RELATIVE_AXIS, "rel_axis"),
    "position_mode4_speed": NativeKey(C.POSITION_MODE4_ABSOLUTE_AXIS, "speed"),
    "position_mode4_acc": NativeKey(C.POSITION_MODE4_ABSOLUTE_AXIS, "acc"),
    "position_mode4_abs_axis": NativeKey(C.POSITION_MODE4_ABSOLUTE_AXIS, "abs_axis"),
    "raw_encoder_value": NativeKey(C.READ_RAW_ENCODER_VALUE, "value"),
    "version_information": NativeKey(C.READ_VERSION_INFORMATION, "version"),
    "user_id": NativeKey(C.USER_ID, "id"),
    "heartbeat_protection_time": NativeKey(C.SET_HEARTBEAT_PROTECTION_TIME, "times"),
    "write_io_out2_mask": NativeKey(C.WRITE_IO_PORT, "out2_mask"),
    "write_io_out1_mask": NativeKey(C.WRITE_IO_PORT, "out1_mask"),
    "write_io_out2": NativeKey(C.WRITE_IO_PORT, "out2"),
    "write_io_out1": NativeKey(C.WRITE_IO_PORT, "out1"),
    "en_trigger_zero_return": NativeKey(C.SET_POSITION_ERROR_PROTECTION, "en_zero_return"),
    "position_error_protection": NativeKey(C.SET_POSITION_ERROR_PROTECTION, "enable"),
    "position_error_time": NativeKey(C.SET_POSITION_ERROR_PROTECTION, "time"),
    "position_error_count": NativeKey(C.SET_POSITION_ERROR_PROTECTION, "errors"),
    "position_threshold_enable": NativeKey(C.SET_POSITION_THRESHOLD, "enable"),
    "position_threshold": NativeKey(C.SET_POSITION_THRESHOLD, "values"),
    "sync_enable": NativeKey(C.SET_SYNC, "enable"),
    "iap_control": NativeKey(C.IAP_CONTROL, "cmd"),
    **{f"vfoc_{k}": NativeKey(C.SET_VFOC_PID, k) for k in ("kp", "ki", "kd", "kv")},
    **{f"close_{k}": NativeKey(C.SET_CLOSE_PID, k) for k in ("kp", "ki", "kd", "kv")},
    "pulse_divider_level": NativeKey(C.SET_PULSE_DIVIDER, "level"),
    "pulse_divider_period": NativeKey(C.SET_PULSE_DIVIDER, "period"),
    "in1_port_mode": NativeKey(C.SET_IN1_PORT_MODE, "type"),
}
del C

#: the native protocol's map: parameter name -> command code + message field
MKS_NATIVE: ParamMap[NativeKey] = ParamMap("mks-serial", MKS_PARAMS, MappingProxyType(_KEYS))


def fields_of(command: int) -> tuple[str, ...]:
    """Parameter names carried by one command, in the map's order (all of them go in one frame)."""
    return tuple(name for name, key in _KEYS.items() if key.command == command)
