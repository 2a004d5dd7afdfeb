"""ZeroErr eRob rotary actuator: Modbus RTU register table.

Source: "eRob Modbus RTU User Manual" v1.6 (EN), chapter 4 "Parameter Register Address"
(``../shared/manuals/erob-modbus-rtu-manual-v1.6-en.txt``), cross-checked against the
v1.3 Chinese manual.

Rules of this table:

* Every register of chapter 4 is here, plus one register that chapter 4 omits:
  0x00D8-0x00D9 "Torque Control Mode Max. Speed", known only from the torque-control
  example of section 5.3.2 (step 3), see ERRATA DOC-EROB-EN-2.
* A (Hi)/(Lo) register pair is ONE entry at its Hi address, type ``int32``. All eRob
  32-bit values are signed and travel **Hi word first** (``low_word_first=False``).
* Single registers are ``uint16``; the only signed one is the power-stage temperature
  (``int16``, it can read below 0 degC).
* Names are the manual's Definition column put through
  :func:`joints.devices.registers.snake_name` ("(Hi)"/"(Lo)" dropped, runs of
  non-alphanumerics -> "_", lowercase), keeping the manual's spelling ("Struck" = stall).
  :data:`MANUAL_DEFINITIONS` keeps the printed definition of every entry.
* Units: "count" (output encoder counts, :data:`COUNTS_PER_REV` per output turn),
  "count/s", "count/s^2", "mA", "mV", "ms", "0.05 ms", "degC", "mNm", "bps"; "" where the
  manual prints "—".
* ``persistent=True`` marks writes that are persistent or dangerous (they change the bus
  address/speed after a restart, write flash, or wipe the multi-turn count).
"""

from __future__ import annotations

import enum

from joints.devices.registers import Access, Register, RegisterTable

__all__ = [
    "COUNTS_PER_REV",
    "EROB_MODBUS",
    "MANUAL_DEFINITIONS",
    "STATUS_BLOCK_START",
    "STATUS_BLOCK_WORDS",
    "AchieveStatus",
    "BaudRate",
    "MotionMode",
    "MotionStatus",
    "OperationMode",
]

#: Output-shaft encoder resolution (19-bit single-turn): counts per output revolution.
COUNTS_PER_REV = 524288


class OperationMode(enum.IntEnum):
    """Values of ``operation_mode`` (0x0040)."""

    TORQUE = 1
    SPEED = 2
    POSITION = 3


class MotionMode(enum.IntEnum):
    """Values of ``motion_mode`` (0x0041); relative moves use ABSOLUTE + target_relative_position."""

    CONTINUOUS = 0
    ABSOLUTE = 1
    REPETITIVE = 2


class MotionStatus(enum.IntEnum):
    """Values of ``motion_status`` (0x0061); 2 is not documented."""

    STOP = 0
    MOVING = 1
    STOP_REPETITIVE = 3


class AchieveStatus(enum.IntEnum):
    """Values of ``status_of_achieving_position`` (0x0063)."""

    MOTOR_OFF = 0  #: disabled, brake engaged
    MOTOR_ON = 1  #: enabled, brake released
    OPERATION = 2  #: moving
    WAIT_TIME = 3  #: in the target window, waiting for the settle time to elapse
    TARGET_REACHED = 4


class BaudRate(enum.IntEnum):
    """Codes of ``modbus_baud_rate`` (0x0001)."""

    B9600 = 1
    B19200 = 2
    B38400 = 3
    B115200 = 4

    @property
    def bps(self) -> int:
        """The line speed in bit/s."""
        return _BPS[self]

    @classmethod
    def from_bps(cls, bps: int) -> BaudRate:
        """The code for a line speed in bit/s (ValueError if the drive does not support it)."""
        for code, rate in _BPS.items():
            if rate == bps:
                return code
        raise ValueError(f"eRob Modbus: unsupported baud rate {bps} (choose {sorted(_BPS.values())})")


_BPS: dict[BaudRate, int] = {
    BaudRate.B9600: 9600,
    BaudRate.B19200: 19200,
    BaudRate.B38400: 38400,
    BaudRate.B115200: 115200,
}

#: Manual definition (as printed, Hi row for pairs) of every register, by register name.
MANUAL_DEFINITIONS: dict[str, str] = {}

_R, _RW, _CMD = Access.R, Access.RW, Access.COMMAND


def _reg(
    address: int,
    definition: str,
    name: str,
    type: str = "uint16",
    access: Access = Access.RW,
    unit: str = "",
    description: str = "",
    *,
    minimum: int | None = None,
    maximum: int | None = None,
    default: int = 0,
    persistent: bool = False,
) -> Register:
    """One table entry; records the manual's definition text for the name check."""
    MANUAL_DEFINITIONS[name] = definition
    return Register(
        address=address,
        name=name,
        type=type,
        access=access,
        unit=unit,
        description=description,
        minimum=minimum,
        maximum=maximum,
        default=default,
        persistent=persistent,
        low_word_first=False,
    )


EROB_MODBUS: RegisterTable = RegisterTable.build(
    "erob",
    [
        # ---- Basic parameters -------------------------------------------------------------
        _reg(0x0000, "Modbus Address", "modbus_address", "uint16", _RW, "",
             "Slave address (1..255; 0 is the broadcast address). Takes effect only after "
             "Save Parameters and a power cycle.",
             minimum=1, maximum=255, persistent=True),
        _reg(0x0001, "Modbus Baud Rate", "modbus_baud_rate", "uint16", _RW, "bps",
             "Baud-rate code, not bit/s: 1 = 9600, 2 = 19200, 3 = 38400, 4 = 115200 "
             "(see BaudRate). Takes effect after save and restart.",
             minimum=1, maximum=4, persistent=True),
        _reg(0x0002, "Modbus Communication Timeout Duration.",
             "modbus_communication_timeout_duration", "uint16", _RW, "ms",
             "0 = watchdog off (default). 1..4000 ms: once the first Modbus frame has been "
             "received, a gap longer than this raises the 'RS485 communication timeout' "
             "error 0xFA2 (4002).",
             minimum=0, maximum=4000, default=0),
        # ---- Performance parameters -------------------------------------------------------
        _reg(0x0030, "Position Loop Gain", "position_loop_gain", "uint16", _RW, "",
             "Position-loop proportional gain (no unit given)."),
        _reg(0x0031, "Speed Loop Gain", "speed_loop_gain", "uint16", _RW, "",
             "Speed-loop proportional gain (no unit given)."),
        _reg(0x0032, "Speed Loop Integral", "speed_loop_integral", "uint16", _RW, "",
             "Speed-loop integral term (no unit given)."),
        # ---- Control parameters -----------------------------------------------------------
        _reg(0x0040, "Operation Mode", "operation_mode", "uint16", _RW, "",
             "Control mode: 1 = torque, 2 = speed, 3 = position (see OperationMode).",
             minimum=1, maximum=3),
        _reg(0x0041, "Motion Mode", "motion_mode", "uint16", _RW, "",
             "Position-mode motion type: 0 = move continuous, 1 = move absolute (also used "
             "for relative moves), 2 = move repetitive (see MotionMode).",
             minimum=0, maximum=2),
        _reg(0x0042, "Control Source", "control_source", "uint16", _RW, "",
             "Command source: 0 = none (Modbus control, as in every example), 1 = EtherCAT.",
             minimum=0, maximum=1),
        _reg(0x0043, "Target Absolute Position (Hi)", "target_absolute_position", "int32", _RW,
             "count", "Absolute target of the output shaft for move-absolute."),
        _reg(0x0045, "Target Relative Position (Hi)", "target_relative_position", "int32", _RW,
             "count", "Relative move distance from the current position (default 0)."),
        _reg(0x0047, "Profile Speed (Hi)", "profile_speed", "int32", _RW, "count/s",
             "Cruise speed of position-mode profiles."),
        _reg(0x0049, "Profile Acceleration (Hi)", "profile_acceleration", "int32", _RW,
             "count/s^2", "Profile acceleration."),
        _reg(0x004B, "Profile Deceleration (Hi)", "profile_deceleration", "int32", _RW,
             "count/s^2", "Profile deceleration (Stop Operating ramps down with it, per the v1.3 CN manual)."),
        _reg(0x004D, "Dwell Time (Hi)", "dwell_time", "int32", _RW, "0.05 ms",
             "Pause before a repetitive move reverses direction."),
        _reg(0x004F, "Target Current (Hi)", "target_current", "int32", _RW, "mA",
             "Current set-point in torque mode; negative values give reverse torque."),
        _reg(0x0051, "Target Speed (Hi)", "target_speed", "int32", _RW, "count/s",
             "Speed set-point in speed mode; negative values turn in reverse."),
        # ---- Status parameters ------------------------------------------------------------
        _reg(0x0060, "Error Code", "error_code", "uint16", _R, "",
             "Active error code, 0 = none. Codes are listed in section 7.2 of the eRob "
             "CANopen/EtherCAT user manual (e.g. 0xFA2 = RS485 communication timeout)."),
        _reg(0x0061, "Motion Status", "motion_status", "uint16", _R, "",
             "0 = stopped, 1 = moving, 3 = repetitive motion stopped (see MotionStatus)."),
        _reg(0x0063, "Status of Achieving Position", "status_of_achieving_position", "uint16",
             _R, "",
             "0 = motor off (disabled, brake on), 1 = motor on (enabled, brake off), "
             "2 = operating, 3 = waiting for the settle time, 4 = target reached "
             "(see AchieveStatus)."),
        _reg(0x0064, "Given Position (Hi)", "given_position", "int32", _R, "count",
             "Position command currently fed to the position loop."),
        _reg(0x0066, "Actual Position (Hi)", "actual_position", "int32", _R, "count",
             "Measured output-shaft position (called Position Feedback before v1.6)."),
        _reg(0x0068, "Position Error (Hi)", "position_error", "int32", _R, "count",
             "Following error: commanded minus actual position."),
        _reg(0x006C, "Given Speed (Hi)", "given_speed", "int32", _R, "count/s",
             "Speed command currently fed to the speed loop."),
        _reg(0x006E, "Current Speed (Hi)", "current_speed", "int32", _R, "count/s",
             "Measured output-shaft speed."),
        _reg(0x0070, "Speed Error (Hi)", "speed_error", "int32", _R, "count/s",
             "Speed-loop error: commanded minus measured speed."),
        _reg(0x0072, "Given Current (Hi)", "given_current", "int32", _R, "mA",
             "Current command currently fed to the current loop."),
        _reg(0x0074, "Motor Current (Hi)", "motor_current", "int32", _R, "mA",
             "Measured motor current."),
        _reg(0x0076, "Bus Voltage (Hi)", "bus_voltage", "int32", _R, "mV",
             "Measured DC bus voltage."),
        _reg(0x0078, "Part of Power Temperature", "part_of_power_temperature", "int16", _R,
             "degC", "Power-stage temperature; the sensor covers -20..150 degC."),
        _reg(0x0079, "Position Reaches Set Precision", "position_reaches_set_precision",
             "uint16", _RW, "count",
             "In-position window: the target counts as reached within this many counts."),
        _reg(0x007A, "Time Setting of Achieving Position", "time_setting_of_achieving_position",
             "uint16", _RW, "0.05 ms",
             "Settle time the position must stay inside the window before 'target reached'."),
        _reg(0x007B, "Torque Sensor Value (Hi)", "torque_sensor_value", "int32", _R, "mNm",
             "Output torque from the built-in torque sensor; only on modules fitted with one."),
        _reg(0x007D, "Dual Encoder Difference Value (Hi)", "dual_encoder_difference_value",
             "int32", _R, "count",
             "Load-side minus motor-side encoder position (referred to the motor side); shows "
             "the elastic wind-up of the gearbox."),
        _reg(0x007F, "Position Offset (Hi)", "position_offset", "int32", _RW, "count",
             "Offset applied to target and actual position when the motor is stopped "
             "(zero-position calibration, chapter 7; persist with Save Parameters)."),
        # ---- Protection setting parameters ------------------------------------------------
        _reg(0x00B0, "Continuous Current (Hi)", "continuous_current", "int32", _RW, "mA",
             "Continuous (rated) current limit."),
        _reg(0x00B2, "Peak Current (Hi)", "peak_current", "int32", _RW, "mA",
             "Peak current limit."),
        _reg(0x00B4, "Peak Current Time", "peak_current_time", "uint16", _RW, "ms",
             "How long the peak current may last."),
        _reg(0x00B5, "Max. Speed (Hi)", "max_speed", "int32", _RW, "count/s",
             "Speed limit."),
        _reg(0x00B7, "Max. Acceleration (Hi)", "max_acceleration", "int32", _RW, "count/s^2",
             "Acceleration limit."),
        _reg(0x00B9, "Max. Position Error (Hi)", "max_position_error", "int32", _RW, "count",
             "Limit of the following error (no further description in the manual)."),
        _reg(0x00BB, "Max. Speed Error (Hi)", "max_speed_error", "int32", _RW, "count/s",
             "Limit of the speed error (no further description in the manual)."),
        _reg(0x00BD, "Min. Position Limit Value (Hi)", "min_position_limit_value", "int32", _RW,
             "count", "Lower software position limit."),
        _reg(0x00BF, "Max. Position Limit Value (Hi)", "max_position_limit_value", "int32", _RW,
             "count", "Upper software position limit."),
        _reg(0x00C1, "Max. Phase Current (Hi)", "max_phase_current", "int32", _RW, "mA",
             "Phase-current limit."),
        _reg(0x00C3, "Max. Motor Current (Hi)", "max_motor_current", "int32", _RW, "mA",
             "Motor-current limit."),
        _reg(0x00C5, "Struck Current (Hi)", "struck_current", "int32", _RW, "mA",
             "Stall (locked-rotor) protection current; 'Struck' is the manual's spelling for stall."),
        _reg(0x00C7, "Struck Speed (Hi)", "struck_speed", "int32", _RW, "count/s",
             "Stall protection speed (no further description in the manual)."),
        _reg(0x00C9, "Struck Time", "struck_time", "uint16", _RW, "0.05 ms",
             "Stall protection time (no further description in the manual)."),
        _reg(0x00CA, "Min. Permissible Bus Voltage (Hi)", "min_permissible_bus_voltage",
             "int32", _RW, "mV", "Under-voltage threshold of the DC bus."),
        _reg(0x00CC, "Max. Permissible Bus Voltage (Hi)", "max_permissible_bus_voltage",
             "int32", _RW, "mV", "Over-voltage threshold of the DC bus."),
        _reg(0x00D1, "Power Temperature Protection Value", "power_temperature_protection_value",
             "uint16", _RW, "degC",
             "Over-temperature threshold of the power stage; the manual recommends setting "
             "it to 85 degC or less (see the safety guide of the actuator manual)."),
        _reg(0x00D8, "Torque Control Mode Max. Speed (Hi)", "torque_control_mode_max_speed",
             "int32", _RW, "count/s",
             "Speed limit while in torque mode. Missing from the chapter-4 table; known only "
             "from the section 5.3.2 example, step 3 (ERRATA DOC-EROB-EN-2). The example "
             "writes 0 yet the motor then turns, so 0 may mean 'no limit' (DOC-EROB-EN-6)."),
        # ---- Control commands -------------------------------------------------------------
        _reg(0x00F0, "Enable the Motor", "enable_the_motor", "uint16", _CMD, "",
             "0 = disable (motor off, brake engages), 1 = enable (motor on, brake releases). "
             "Wait about 500 ms after enabling before Start Operating.",
             minimum=0, maximum=1),
        _reg(0x00F1, "Start Operating", "start_operating", "uint16", _CMD, "",
             "Any write starts the motion set up in the control registers."),
        _reg(0x00F2, "Stop Operating", "stop_operating", "uint16", _CMD, "",
             "Any write stops the motion (the v1.3 CN manual: ramps down with the profile "
             "deceleration)."),
        _reg(0x00F3, "Emergency Stop", "emergency_stop", "uint16", _CMD, "",
             "Any write stops within 50 ms; the hard braking can regenerate enough to trip "
             "the bus over-voltage alarm."),
        _reg(0x00F4, "Stop Repetitive Motion", "stop_repetitive_motion", "uint16", _CMD, "",
             "Any write ends a repetitive move: it returns to its start point or stops when "
             "it reaches the target."),
        _reg(0x00F6, "Clear Errors", "clear_errors", "uint16", _CMD, "",
             "Writing a non-zero value clears the errors."),
        _reg(0x00F7, "Save Parameters", "save_parameters", "uint16", _CMD, "",
             "Any write stores the parameters in flash (the examples write 2). Takes about "
             "3 s; do not cut power meanwhile or the parameters are lost.",
             persistent=True),
        _reg(0x00F9, "Reset Output Encoder", "reset_output_encoder", "uint16", _CMD, "",
             "Any write resets the output (load) encoder, to clear a multi-turn battery alarm "
             "after fixing its cause. Used otherwise it wipes the multi-turn count.",
             persistent=True),
    ],
)

#: Start of the contiguous status block error_code (0x0060) .. part_of_power_temperature (0x0078).
STATUS_BLOCK_START = 0x0060
#: Words in that block, gaps (0x0062, 0x006A-0x006B) included: one FC 0x03 read of 25 registers.
STATUS_BLOCK_WORDS = 0x0079 - 0x0060
