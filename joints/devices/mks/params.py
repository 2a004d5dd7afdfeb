"""The MKS SERVO42D/57D parameters, defined once for the native protocol and Modbus mode.

Rule: pure data. Every quantity of the manual's Parts 5, 6 and 8 is one
:class:`~joints.devices.params.Param`, named after the manual in snake_case; the native map
(:mod:`joints.devices.mks.native`, command code + field) and the Modbus map
(:mod:`joints.devices.mks.modbus`, function + register + byte field) reach them by the same names,
so switching a bus's protocol changes nothing above the driver. Source:
mks-servo42d-57d-rs485-manual-v1.0.5.

Values are the manual's raw values (the wire value of the native command, which is also the Modbus
register value): codes for enumerated settings (see :mod:`joints.devices.mks.state` for their
enums), mA for currents, rpm for speeds, the 0..255 ``acc`` of 6.1, pulses (microsteps), encoder
counts (16384 per turn). ``microsteps`` is the count 1..256 (the native codec sends 256 as 0x00).
``holding_current`` is the code 0..8 = 10..90 % (the value list starts at 00 although the header
says "holdMa(01~08)", ERRATA DOC-MKS-9). ``number_of_pulses`` is int32 (DOC-MKS-4).

Access
    Most MKS settings can be written but not read back: ``Access.W``. Reads (5.1, 0xF1) are
    ``Access.R``. Commands whose writing triggers an action (calibrate, go home, set zero,
    restore, restart, release, emergency stop, save/clean, and every field of the run commands:
    writing one sends the whole command) are ``Access.COMMAND``. Commands without data take the
    value 1 (the Modbus register value of Part 8).

Multi-field commands
    0x8C (respond, active), 0x90 (home), 0x94 ("noLimit" home), 0x9A (0_Mode) and the run commands
    0xF6/0xFD/0xFE/0xF4/0xF5 carry several parameters in one frame: writing one of them sends
    the command with the other fields' last written (or default) values. Their names share the
    command's prefix (``home_*``, ``zero_mode_*``, ``speed_mode_*``, ``position_mode1_*`` ...;
    position modes numbered as in 6.6-6.9, see ERRATA DOC-MKS-7).

Persistent / dangerous (``persistent=True``: the driver demands confirmation)
    0x80 calibrate (moves the shaft), 0x8A baud rate and 0x8B address (the host loses the drive),
    0x8E Modbus on/off (switches protocol), 0x9A 0_Mode (moves at power-on), 0xFF save/clean speed
    mode (runs at power-on), 0x3F restore defaults, 0x41 restart, 0x92 set zero.

Per model
    The two drives differ in the working current range and defaults (42D 0-3000 mA, default
    1600; 57D 0-5200 mA, default 3200; Part 3 #3) and the "noLimit" homing current default (42D
    800 mA, 57D 400 mA; Part 3 #23). :data:`MKS_PARAMS` holds the family (bounds wide enough for
    both, 42D defaults); :func:`model_params` gives a model's own set, with the same names.

Added by later firmware (:data:`FEATURE_OF`: parameter -> the firmware feature of
:mod:`joints.devices.quirks` it needs; manual V1.0.9): ``raw_encoder_value`` (0x35, V1.0.6, with
the read/write-all commands), ``version_information`` (0x40, read) and
``heartbeat_protection_time`` (0x98, ms, 0 = off: the drive stops urgently when no command
arrived for that long). A driver or twin whose firmware profile lacks the feature has no such
parameter.

Defaults the manual does not give (choices): ``home_speed`` 60 rpm (menu options 30-180),
``zero_mode_speed`` 2 (middle of 0-4), ``group_address`` 0 (no group), ``motor_enable`` 0.
"""

from __future__ import annotations

from dataclasses import replace

from joints.devices.params import Access, Param, ParamSet

__all__ = ["DANGEROUS", "FEATURE_OF", "MKS_PARAMS", "MODELS", "VALUE_FEATURE_OF", "model_params"]

R, W, C = Access.R, Access.W, Access.COMMAND


def _cmd(name: str, description: str, *, persistent: bool = False) -> Param:
    """A command without data: write 1."""
    return Param(name, "bool", C, "", description, 1, 1, 0, persistent)


_PARAMS: tuple[Param, ...] = (
    # 5.1 read parameter commands (and 0xF1)
    Param("encoder_carry", "int32", R, "turn", "0x30 encoder value (carry): the carry (turns)"),
    Param("encoder_value", "uint16", R, "count", "0x30 encoder value (carry): the value within the turn",
          0, 0x3FFF),
    Param("encoder_addition", "int48", R, "count", "0x31 encoder value (addition): 0x4000 per turn"),
    Param("real_time_speed", "int16", R, "rpm", "0x32 real-time speed of the motor (CCW > 0)"),
    Param("number_of_pulses", "int32", R, "pulse", "0x33 number of pulses received (int32; Part 8: uint32, "
          "ERRATA DOC-MKS-4)"),
    Param("io_status", "uint8", R, "", "0x34 IO ports status: bit0 IN_1, bit1 IN_2, bit2 OUT_1, bit3 OUT_2"),
    Param("angle_error", "int32", R, "1/51200 turn", "0x39 error of the motor shaft angle (51200 = 360 deg)"),
    Param("en_pin_status", "bool", R, "", "0x3A En pins status: 1 enabled, 0 disabled"),
    Param("go_back_to_zero_status", "uint8", R, "", "0x3B go back to zero status when power on: "
          "0 going, 1 success, 2 fail", 0, 2),
    Param("protection_state", "bool", R, "", "0x3E motor shaft locked-rotor protection state: 1 protected"),
    Param("motor_status", "uint8", R, "", "0xF1 motor status: 0 fail, 1 stop, 2 speed up, 3 speed down, "
          "4 full speed, 5 homing, 6 calibrating", 0, 6),
    # commands without data
    _cmd("release_protection", "0x3D release the motor shaft locked-rotor protection state"),
    _cmd("restore_default_parameters", "0x3F restore the default parameters (reboots; calibrate again)",
         persistent=True),
    _cmd("restart_motor", "0x41 restart the motor", persistent=True),
    _cmd("calibrate", "0x80 calibrate the encoder (moves the shaft; unloaded motor only)", persistent=True),
    _cmd("go_home", "0x91 go home (limit switch or 'noLimit' method of 0x94)"),
    _cmd("set_current_axis_to_zero", "0x92 set the current axis to zero", persistent=True),
    _cmd("emergency_stop", "0xF7 emergency stop the motor"),
    # 5.2 set parameters
    Param("work_mode", "uint8", W, "", "0x82 work mode: 0 CR_OPEN, 1 CR_CLOSE, 2 CR_vFOC, 3 SR_OPEN, "
          "4 SR_CLOSE, 5 SR_vFOC", 0, 5, 2),
    Param("working_current", "uint16", W, "mA", "0x83 working current Ma (42D max 3000, 57D max 5200)",
          0, 5200, 1600),
    Param("holding_current", "uint8", W, "", "0x9B holding current percentage: 0 = 10 % ... 8 = 90 % "
          "(OPEN/CLOSE modes only)", 0, 8, 4),
    Param("microsteps", "uint16", W, "", "0x84 subdivision (MStep) 1-256", 1, 256, 16),
    Param("en_active_level", "uint8", W, "", "0x85 active of the En pin: 0 low, 1 high, 2 always (Hold)",
          0, 2, 0),
    Param("motor_direction", "uint8", W, "", "0x86 direction of motor rotation (pulse interface only): "
          "0 CW, 1 CCW", 0, 1, 0),
    Param("auto_screen_off", "bool", W, "", "0x87 auto turn off the screen", 0, 1, 0),
    Param("locked_rotor_protection", "bool", W, "", "0x88 motor shaft locked-rotor protection", 0, 1, 0),
    Param("subdivision_interpolation", "bool", W, "", "0x89 subdivision interpolation (MPlyer)", 0, 1, 1),
    Param("baud_rate", "uint8", W, "", "0x8A baud rate: 1 9600, 2 19200, 3 25000, 4 38400, 5 57600, "
          "6 115200, 7 256000", 1, 7, 4, persistent=True),
    Param("slave_address", "uint8", W, "", "0x8B slave address (0 is broadcast; Modbus 1-247)", 1, 255, 1,
          persistent=True),
    Param("slave_respond", "bool", W, "", "0x8C respond: 0 silences the replies to run commands", 0, 1, 1),
    Param("slave_active", "bool", W, "", "0x8C active: 1 sends completion frames (status 2/3)", 0, 1, 1),
    Param("group_address", "uint8", W, "", "0x8D group address (commands to it get no reply)", 1, 255, 0),
    Param("modbus_rtu", "bool", W, "", "0x8E Modbus-RTU protocol on/off (switches the drive's protocol)",
          0, 1, 0, persistent=True),
    Param("key_lock", "bool", W, "", "0x8F lock the keys", 0, 1, 0),
    # 5.3 home
    Param("home_trigger_level", "uint8", W, "", "0x90 HmTrig: effective level of the end stop: 0 low, 1 high",
          0, 1, 0),
    Param("home_direction", "uint8", W, "", "0x90 HmDir: direction of go home: 0 CW, 1 CCW", 0, 1, 0),
    Param("home_speed", "uint16", W, "rpm", "0x90 HmSpeed: speed of go home", 0, 3000, 60),
    Param("end_limit", "bool", W, "", "0x90 EndLimit: endstop-limit function", 0, 1, 0),
    Param("home_reverse_angle", "uint32", W, "count", "0x94 retValue: reverse angle after 'noLimit' homing "
          "(0x4000 = 360 deg)", 0, 0xFFFFFFFF, 0x2000),
    Param("home_mode", "uint8", W, "", "0x94 hm-Mode: the method of go home: 0 limit switch, 1 no limit switch, "
          "2 single lap to zero (V1.0.9: to the 0x9A zero within one turn, then axis 0 there)", 0, 2, 0),
    Param("home_current", "uint16", W, "mA", "0x94 Hm_Ma: current of 'noLimit' go home", 0, 5200, 800),
    Param("limit_port_remap", "bool", W, "", "0x9E limit port remap (left -> En, right -> Dir)", 0, 1, 0),
    # 5.4 0_Mode
    Param("zero_mode", "uint8", W, "", "0x9A 0_Mode: 0 Disable, 1 DirMode, 2 NearMode (moves at power-on)",
          0, 2, 0, persistent=True),
    Param("zero_mode_set_zero", "bool", W, "", "0x9A Set 0: 0 clean zero, 1 set zero", 0, 1, 0,
          persistent=True),
    Param("zero_mode_speed", "uint8", W, "", "0x9A 0_Speed: 0 slowest .. 4 fastest", 0, 4, 2, persistent=True),
    Param("zero_mode_direction", "uint8", W, "", "0x9A 0_Dir: 0 CW, 1 CCW", 0, 1, 0, persistent=True),
    # 6.2 enable; 6.5 speed mode
    Param("motor_enable", "bool", W, "", "0xF3 enable the motor (serial modes)", 0, 1, 0),
    Param("speed_mode_direction", "uint8", C, "", "0xF6 dir: 0 CCW, 1 CW", 0, 1, 0),
    Param("speed_mode_speed", "uint16", C, "rpm", "0xF6 speed (0 stops)", 0, 3000, 0),
    Param("speed_mode_acc", "uint8", C, "", "0xF6 acc (0 = no ramp)", 0, 255, 0),
    Param("save_clean_speed_mode_parameter", "uint8", C, "", "0xFF state: 0xC8 save, 0xCA clean the "
          "speed-mode parameters (a saved speed mode runs at power-on)", 0xC8, 0xCA, 0, persistent=True),
    # 6.6 - 6.9 position modes
    Param("position_mode1_direction", "uint8", C, "", "0xFD relative motion by pulses: dir 0 CCW, 1 CW", 0, 1, 0),
    Param("position_mode1_speed", "uint16", C, "rpm", "0xFD speed (0 stops)", 0, 3000, 0),
    Param("position_mode1_acc", "uint8", C, "", "0xFD acc", 0, 255, 0),
    Param("position_mode1_pulses", "uint32", C, "pulse", "0xFD pulses (microsteps) to run", 0, 0xFFFFFFFF, 0),
    Param("position_mode2_speed", "uint16", C, "rpm", "0xFE absolute motion by pulses: speed (0 stops)",
          0, 3000, 0),
    Param("position_mode2_acc", "uint8", C, "", "0xFE acc", 0, 255, 0),
    Param("position_mode2_abs_pulses", "int32", C, "pulse", "0xFE absPulses: the absolute pulses"),
    Param("position_mode3_speed", "uint16", C, "rpm", "0xF4 relative motion by axis: speed (0 stops)",
          0, 3000, 0),
    Param("position_mode3_acc", "uint8", C, "", "0xF4 acc", 0, 255, 0),
    Param("position_mode3_rel_axis", "int32", C, "count", "0xF4 relAxis: relative axis (encoder counts)"),
    Param("position_mode4_speed", "uint16", C, "rpm", "0xF5 absolute motion by axis: speed (0 stops)",
          0, 3000, 0),
    Param("position_mode4_acc", "uint8", C, "", "0xF5 acc", 0, 255, 0),
    Param("position_mode4_abs_axis", "int32", C, "count", "0xF5 absAxis: absolute axis (encoder counts)"),
    # V1.0.6
    Param("raw_encoder_value", "int48", R, "count", "0x35 raw accumulated multi-turn encoder value (V1.0.6): "
          "0x4000 per turn since power-on (no zero applied)"),
    # V1.0.9
    Param("version_information", "uint32", R, "", "0x40 version (V1.0.9): b31-b28 calibrated, b27-b24 hardware "
          "version, b23-b0 firmware version major.minor.patch"),
    # 0x36 write the IO port (V1.0.6; RS485 6.3, Modbus 4.2): mask 1 writes the value, 0 / 2 leave the port
    Param("write_io_out2_mask", "uint8", C, "", "0x36 OUT2_mask: 0 do not write OUT_2, 1 write, 2 keep (V1.0.6)",
          0, 2, 0),
    Param("write_io_out1_mask", "uint8", C, "", "0x36 OUT1_mask: 0 do not write OUT_1, 1 write, 2 keep (V1.0.6)",
          0, 2, 0),
    Param("write_io_out2", "uint8", C, "", "0x36 OUT_2 value (0/1) (V1.0.6)", 0, 1, 0),
    Param("write_io_out1", "uint8", C, "", "0x36 OUT_1 value (0/1) (V1.0.6)", 0, 1, 0),
    # 0x9D position-error protection and En-triggered single-turn zero return (V1.0.6; RS485 V1.0.6 5.10,
    # V1.0.9 5.4.2; Modbus V1.0.9 3.4.2)
    Param("en_trigger_zero_return", "bool", W, "", "0x9D g0Enable: an En pulse of ~200 ms starts the single-turn "
          "zero return (0_Mode), no more at power-on (the motor MOVES on the En line) (V1.0.6)", 0, 1, 0,
          persistent=True),
    Param("position_error_protection", "bool", W, "", "0x9D pEnable: position-error protection on (V1.0.6)",
          0, 1, 0),
    Param("position_error_time", "uint16", W, "15 ms", "0x9D Tim: the error statistics time, ~15 ms per unit "
          "(V1.0.6)", 0, 0xFFFF, 20),
    Param("position_error_count", "uint16", W, "1/28000 turn", "0x9D Errors: the position error that protects "
          "(28000 = 360 degrees) (V1.0.6)", 0, 0xFFFF, 14000),
    # 0x95 position-reached threshold (V1.0.8; RS485 V1.0.9 5.2.17)
    Param("position_threshold_enable", "bool", W, "", "0x95 enable: a position move completes only within the "
          "threshold (V1.0.8)", 0, 1, 1),
    Param("position_threshold", "uint16", W, "1/65536 turn", "0x95 values: the position-reached threshold "
          "(65535 = 360 degrees) (V1.0.8)", 0, 0xFFFF, 200),
    # 0xF6 with a run time (V1.0.7; RS485 V1.0.9 10.1, Modbus V1.0.9 8.1)
    Param("speed_mode_run_time", "uint32", C, "10 ms", "0xF6 runTime: stop by itself after this long; 0 = the "
          "frame without it (V1.0.7)", 0, 0x0FFFFFFF, 0),
    # 0x50 IAP control (V1.0.8; RS485 V1.0.9 5.6, Modbus V1.0.9 3.6)
    Param("iap_control", "uint8", C, "", "0x50 IAP: 1 enter the boot loader (the drive restarts and waits for a "
          "firmware file), 2 enter / 3 leave the silent state (V1.0.8)", 1, 3, 3, persistent=True),
    # 0x96 / 0x97 PID parameters (V1.0.8; RS485 V1.0.9 5.3, Modbus V1.0.9 3.3): "users are advised against
    # adjusting the PID parameters ... to avoid damaging the motor" - persistent, confirm
    *(Param(f"{mode}_{k}", "uint16", W, "", f"0x{code:02X} {mode.upper()} mode PID {k.capitalize()} (0-1024) "
            "(V1.0.8)", 0, 1024, default, persistent=True)
      for mode, code, gains in (("vfoc", 0x96, (("kp", 0xDC), ("ki", 0x64), ("kd", 0x10E), ("kv", 0x140))),
                                ("close", 0x97, (("kp", 0xC8), ("ki", 0x50), ("kd", 0xFA), ("kv", 0x12C))))
      for k, default in gains),
    # 0x83 while running, not saved (V1.0.7; RS485 V1.0.9 5.2.3, Modbus V1.0.9 3.2.3)
    Param("working_current_unsaved", "bool", W, "", "0x83 with the trailing 00 (Modbus: bit 15 of Current): change "
          "the working current now, do not save it (V1.0.7)", 0, 1, 0),
    # 0x3B's second status (V1.0.7; RS485 V1.0.9 5.1.8)
    Param("homing_status", "uint8", R, "", "0x3B status2: the non-single-turn zero return (go home 0x91): 0 going, "
          "1 success, 2 not homed or failed (V1.0.7)", 0, 2),
    # 0x42 user ID (V1.0.9; RS485 V1.0.9 5.1.12): read without data, written with 4 bytes
    Param("user_id", "uint32", Access.RW, "", "0x42 user ID: a number of the user's own to identify the motor (V1.0.9)",
          0, 0xFFFFFFFF, 0),
    # 0x91 goZeroMode (V1.0.9; RS485 V1.0.9 7.3.6 native 0 / 1, Modbus V1.0.9 5.3.6 register 1 / 2)
    Param("go_home_mode", "uint8", C, "", "0x91 goZeroMode: 0 origin homing (search), 1 coordinate homing (run to "
          "the coordinate zero point, no search) (V1.0.9)", 0, 1, 0),
    # 0x4A synchronization flag (V1.0.8; RS485 V1.0.9 12.4.1)
    Param("sync_enable", "bool", W, "", "0x4A synchronization: run commands wait for the broadcast 0x4B (V1.0.8)",
          0, 1, 0),
    Param("heartbeat_protection_time", "uint32", W, "ms", "0x98 heartbeat protection time (V1.0.9): no command "
          "for this long stops the motor urgently; 0 = off", 0, 0xFFFFFFFF, 0),
    # 0x99 pulse frequency division output (V1.0.9; RS485 V1.0.9 6.4, Modbus V1.0.9 4.3; 57D only)
    Param("pulse_divider_level", "uint8", W, "", "0x99 divLevel: start level of the OUT_2 pulse divider output, "
          "0 low, 1 high (57D) (V1.0.9)", 0, 1, 0),
    Param("pulse_divider_period", "uint32", W, "pulses", "0x99 divPeriod: OUT_2 toggles once every divPeriod "
          "pulses; below 100 no divider output (57D) (V1.0.9)", 0, 0xFFFFFFFF, 0),
    # 0x9F port mode (V1.0.9; RS485 V1.0.9 6.2; 28D/35D/42D only): IN_1 as an output disables its switch input
    Param("in1_port_mode", "uint8", W, "", "0x9F IN_1 port mode: 0 input (default), 1 output, written by 0x36 "
          "bit 2 (28D/35D/42D) (V1.0.9)", 0, 1, 0, persistent=True),
)

#: parameters a later firmware added -> the feature (joints.devices.quirks) a firmware profile needs for them
FEATURE_OF: dict[str, str] = {"raw_encoder_value": "mks-all-parameters", "version_information": "mks-version",
                              "heartbeat_protection_time": "mks-heartbeat",
                              **{n: "mks-write-io" for n in ("write_io_out2_mask", "write_io_out1_mask", "write_io_out2",
                                                             "write_io_out1")},
                              **{n: "mks-position-error-protection" for n in (
                                  "en_trigger_zero_return", "position_error_protection", "position_error_time",
                                  "position_error_count")},
                              "position_threshold_enable": "mks-position-threshold",
                              "position_threshold": "mks-position-threshold", "sync_enable": "mks-sync", "iap_control": "mks-iap",
                              "working_current_unsaved": "mks-current-unsaved", "homing_status": "mks-homing-status",
                              **{f"{m}_{k}": "mks-pid" for m in ("vfoc", "close") for k in ("kp", "ki", "kd", "kv")},
                              "speed_mode_run_time": "mks-timed-speed", "go_home_mode": "mks-coordinate-homing",
                              "user_id": "mks-user-id", "pulse_divider_level": "mks-pulse-divider",
                              "pulse_divider_period": "mks-pulse-divider", "in1_port_mode": "mks-in1-port-mode"}

#: values a later firmware added to a parameter's range -> the feature a firmware profile needs for them
VALUE_FEATURE_OF: dict[tuple[str, int], str] = {("home_mode", 2): "mks-single-lap-home"}

MKS_PARAMS: ParamSet = ParamSet("mks-servo42d57d", _PARAMS)

#: names whose writing needs confirmation (the issue's dangerous commands)
DANGEROUS: frozenset[str] = frozenset(p.name for p in _PARAMS if p.persistent)

#: per-model differences: name -> (maximum, default)
_MODEL_LIMITS: dict[str, dict[str, tuple[int, int]]] = {
    "mks-servo42d": {"working_current": (3000, 1600), "home_current": (3000, 800)},
    "mks-servo57d": {"working_current": (5200, 3200), "home_current": (5200, 400)},
}
MODELS = tuple(_MODEL_LIMITS)


def model_params(model: str) -> ParamSet:
    """The parameters of one model ("mks-servo42d" or "mks-servo57d"): the family's names with
    that model's current range and defaults."""
    limits = _MODEL_LIMITS.get(model)
    if limits is None:
        raise ValueError(f"unknown MKS model {model!r} (allowed: {', '.join(MODELS)})")
    return ParamSet(model, (replace(p, maximum=limits[p.name][0], default=limits[p.name][1])
                            if p.name in limits else p for p in MKS_PARAMS))
