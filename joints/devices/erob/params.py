"""The eRob's parameters, defined once for every protocol that reaches the drive.

Rule: the Modbus manual's chapter-4 table (:data:`joints.devices.erob.registers.EROB_MODBUS`) is
the base: each of its registers is one parameter by the same name. Quantities that only the CAN
custom protocol or CANopen reach are added here as :class:`~joints.devices.params.Param` entries,
so every protocol map (Modbus register, CAN index, CANopen object) names the same quantities.
"""

from __future__ import annotations

from joints.devices.erob.registers import EROB_MODBUS
from joints.devices.params import Access, Param, ParamSet

#: quantities no Modbus register carries (added by the CAN custom protocol and CANopen maps)
OTHER_PROTOCOLS: tuple[Param, ...] = (
    # --- CAN custom protocol (eRunner 7.5) ---
    # Quantities only the eRob CAN custom protocol reaches (eRunner manual v1.7, 7.5.1/7.5.2 and the
    # examples of 4.2/4.3/7.4.4/7.4.5); their CAN indexes are in joints.devices.erob.can.
    Param("hardware_version", "uint32", Access.R, "",
          "Hardware version of the module, in decimal (e.g. 1005); index 0x0001 subindex 3."),
    Param("firmware_version", "uint32", Access.R, "",
          "Firmware version of the module, in decimal; index 0x0001 subindex 4. Module information "
          "(index 0x0232) needs firmware X5061715X or later."),
    Param("u_phase_current", "int32", Access.R, "mA", "Motor U-phase current."),
    Param("v_phase_current", "int32", Access.R, "mA", "Motor V-phase current."),
    Param("w_phase_current", "int32", Access.R, "mA", "Motor W-phase current."),
    Param("u_phase_voltage", "int32", Access.R, "mV",
          "Motor U-phase voltage (the manual prints the unit mA, ERRATA DOC-EROB-CAN-3)."),
    Param("v_phase_voltage", "int32", Access.R, "mV", "Motor V-phase voltage."),
    Param("w_phase_voltage", "int32", Access.R, "mV", "Motor W-phase voltage."),
    Param("digital_inputs", "uint32", Access.R, "",
          "External input states, bit0..bit5 = IN1..IN6 (1 = on); joint modules have IN1..IN2 only."),
    Param("analog_input", "int32", Access.R, "mV", "External analog input."),
    Param("can_address", "uint8", Access.RW, "",
          "CAN node id of the joint (requests on 0x640 + id, replies on 0x5C0 + id); changing it "
          "moves the drive to another id.", minimum=1, maximum=127, persistent=True),
    Param("can_baud_rate", "uint32", Access.R, "bps",
          "CAN bit rate; fixed at 1 Mbit/s, cannot be changed.", default=1000000),
    Param("jerk_setting", "uint8", Access.RW, "",
          "Jerk (acceleration ramp) time code: 0 = 50 us, 1 = 100 us, 2 = 200 us, 3 = 400 us, "
          "4 = 800 us, 5 = 1600 us, 6 = 3200 us, 7 = 6400 us, 8 = 12800 us, 9 = 25600 us.",
          minimum=0, maximum=9),
    Param("emergency_stop_deceleration", "int32", Access.RW, "count/s^2",
          "Deceleration of the emergency stop on a temperature alarm or at a position limit "
          "(the manual's name is 'emergency stop speed')."),
    Param("motor_angle", "int32", Access.R, "count", "Motor-side encoder position."),
    Param("apply_acceleration_limits_to_all_motions", "uint8", Access.RW, "",
          "0 = motions are limited by the max speed only, 1 = also by the profile acceleration and "
          "deceleration.", minimum=0, maximum=1),
    Param("load_angle", "int32", Access.R, "count", "Load-side encoder single-turn position."),
    Param("phase_current_sum_error", "int32", Access.RW, "mA",
          "Allowed error of the sum of the U, V and W phase currents."),
    Param("use_bus_to_tune_pid", "uint8", Access.RW, "",
          "Whether the position/speed loop gains may be changed over the bus: 0 = no, 1 = yes.",
          minimum=0, maximum=1),
    Param("max_output_torque", "uint16", Access.RW, "0.1%",
          "Peak current limit in per mille of the continuous current."),
    Param("analog_quantity_type", "uint16", Access.RW, "",
          "Source of the analog set-point: 0 = internal (set over the bus with analog_quantity_value). "
          "Known only from the examples (index 0x01FD, ERRATA DOC-EROB-CAN-2)."),
    Param("analog_quantity_value", "int32", Access.RW, "",
          "The set-point in speed mode (target speed, count/s) and torque mode (target current, mA); "
          "0 stops. Known only from the examples (index 0x01FE, ERRATA DOC-EROB-CAN-2)."),
    Param("module_serial", "uint32", Access.R, "",
          "Module sequence number (decimal); the serial number is the outer-diameter code followed by "
          "this number in 8 digits (7.5.3)."),
    Param("module_model_info", "uint32", Access.R, "",
          "Model bit fields: bit4-7 motor type, bit12-15 reduction ratio, bit16-19 outer diameter "
          "(bit0-3, bit8-11 reserved)."),
    Param("module_configuration", "uint32", Access.R, "",
          "Configuration bit fields: bit0-3 output encoder, bit4-7 torque sensor, bit8-11 "
          "communication type, bit12-15 through-hole diameter, bit16-19 brake, bit20-23 reducer "
          "type, bit24-27 mounting type."),
    Param("hardware_change_id", "uint32", Access.R, "", "Hardware change identifier (decimal)."),
    Param("io_function_id", "uint32", Access.R, "",
          "Whether the CANopen module's PCBA has IO: 0 = no, 1 = yes (EtherCAT modules report 0)."),
    Param("module_version", "uint32", Access.R, "",
          "Version bit fields: bit0-3 motor, bit4-7 motor housing, bit8-11 mechanics (visible), "
          "bit12-15 reducer, bit16-19 driver, bit20-23 mechanics (not visible)."),
    Param("release_brake", "uint16", Access.COMMAND, "",
          "Releases the holding brake: a loaded joint falls. See the actuator manual, chapter 7.",
          persistent=True),
    # --- end CAN custom protocol ---
    # --- CANopen (eRunner chapter 5, CiA 402) ---
    # Objects only CANopen reaches; their indexes, data types and EDS details are in
    # joints.devices.erob.canopen (EROB_CANOPEN). Defaults are CiA 301/402 defaults unless noted
    # (assumptions listed there); COB-ID defaults are the base to which the node id is added.
    Param("device_type", "uint32", Access.R, "", "0x1000 device type: CiA 402 servo drive", default=0x00020192),
    Param("error_register", "uint8", Access.R, "", "0x1001 error register (bit 0 generic error, 1 current, "
          "2 voltage, 3 temperature, 4 communication, 5 profile, 7 manufacturer)"),
    Param("cob_id_sync", "uint32", Access.RW, "", "0x1005 COB-ID of SYNC (bit 30 set = this node produces SYNC); "
          "eRunner writes 0x80 ('disable cob-id sync', fig 5-18)", default=0x80),
    Param("communication_cycle_period", "uint32", Access.RW, "us", "0x1006 SYNC period; eRunner default 1000 us "
          "(chapter 3, connection settings)", default=1000),
    Param("guard_time", "uint16", Access.RW, "ms", "0x100C node-guarding period (0 = off)"),
    Param("life_time_factor", "uint8", Access.RW, "", "0x100D guard time x factor = node life time"),
    Param("cob_id_emcy", "uint32", Access.RW, "", "0x1014 COB-ID of EMCY (+ node id)", default=0x80),
    Param("producer_heartbeat_time", "uint16", Access.RW, "ms", "0x1017 heartbeat period (0 = off)"),
    Param("identity_highest_subindex", "uint8", Access.R, "", "0x1018:00 entries of the identity object",
          default=4),
    Param("vendor_id", "uint32", Access.R, "", "0x1018:01 vendor id"),
    Param("product_code", "uint32", Access.R, "", "0x1018:02 product code"),
    Param("revision_number", "uint32", Access.R, "", "0x1018:03 revision number"),
    Param("serial_number", "uint32", Access.R, "", "0x1018:04 serial number"),
    *(p for n, base in enumerate((0x200, 0x300, 0x400, 0x500), 1) for p in (
        Param(f"rpdo{n}_highest_subindex", "uint8", Access.R, "", f"0x{0x13FF + n:04X}:00 RPDO{n} "
              "communication entries", default=5),
        Param(f"rpdo{n}_cob_id", "uint32", Access.RW, "", f"0x{0x13FF + n:04X}:01 RPDO{n} COB-ID (+ node id; "
              "bit 31 set = not valid; only RPDO1 valid at power-on)", default=base | (0 if n == 1 else 1 << 31)),
        Param(f"rpdo{n}_transmission_type", "uint8", Access.RW, "", f"0x{0x13FF + n:04X}:02 RPDO{n} transmission "
              "type (0..240 apply at the next SYNC, 254/255 apply at once)", default=255),
        Param(f"rpdo{n}_event_timer", "uint16", Access.RW, "ms", f"0x{0x13FF + n:04X}:05 RPDO{n} deadline "
              "(0 = off)"),
    )),
    *(p for n, base in enumerate((0x180, 0x280, 0x380, 0x480), 1) for p in (
        Param(f"tpdo{n}_highest_subindex", "uint8", Access.R, "", f"0x{0x17FF + n:04X}:00 TPDO{n} "
              "communication entries", default=6),
        Param(f"tpdo{n}_cob_id", "uint32", Access.RW, "", f"0x{0x17FF + n:04X}:01 TPDO{n} COB-ID (+ node id; "
              "bit 31 set = not valid, bit 30 set = no RTR; only TPDO1 valid at power-on)",
              default=base | (0 if n == 1 else 1 << 31)),
        Param(f"tpdo{n}_transmission_type", "uint8", Access.RW, "", f"0x{0x17FF + n:04X}:02 TPDO{n} transmission "
              "type (0 acyclic sync, 1..240 every n-th SYNC, 252/253 on RTR, 254/255 on event)", default=255),
        Param(f"tpdo{n}_inhibit_time", "uint16", Access.RW, "100 us", f"0x{0x17FF + n:04X}:03 TPDO{n} minimum "
              "time between two transmissions"),
        Param(f"tpdo{n}_event_timer", "uint16", Access.RW, "ms", f"0x{0x17FF + n:04X}:05 TPDO{n} event period "
              "(0 = only on change)"),
        Param(f"tpdo{n}_sync_start_value", "uint8", Access.RW, "", f"0x{0x17FF + n:04X}:06 TPDO{n} SYNC counter "
              "value of the first transmission (0 = not used)"),
    )),
    # mapping parameters; defaults: the CiA 402 pre-defined mapping (value = index << 16 | subindex << 8 | bits)
    *(p for kind, first, maps in (
        ("rpdo", 0x1600, ((0x60400010,), (0x60400010, 0x60600008), (0x60400010, 0x607A0020),
                          (0x60400010, 0x60FF0020))),
        ("tpdo", 0x1A00, ((0x60410010,), (0x60410010, 0x60610008), (0x60410010, 0x60640020),
                          (0x60410010, 0x606C0020))),
    ) for n, entries in enumerate(maps, 1) for p in (
        Param(f"{kind}{n}_mapped_objects", "uint8", Access.RW, "", f"0x{first + n - 1:04X}:00 {kind.upper()}{n} "
              "number of mapped objects", maximum=8, default=len(entries)),
        *(Param(f"{kind}{n}_mapping_{i}", "uint32", Access.RW, "", f"0x{first + n - 1:04X}:{i:02X} "
                f"{kind.upper()}{n} mapped object {i}", default=entries[i - 1] if i <= len(entries) else 0)
          for i in range(1, 9)),
    )),
    Param("controlword", "uint16", Access.RW, "", "0x6040 CiA 402 controlword (devices.cia402)"),
    Param("statusword", "uint16", Access.R, "", "0x6041 CiA 402 statusword (devices.cia402)"),
    Param("quick_stop_option_code", "int16", Access.RW, "", "0x605A quick stop reaction (2 = stop on the "
          "quick-stop ramp, then switch-on disabled)", default=2),
    Param("modes_of_operation", "int8", Access.RW, "", "0x6060 requested mode (1 PP, 3 PV, 4 PT, 7 IP, 8 CSP, "
          "9 CSV, 10 CST; not the Modbus operation_mode codes); change it only out of OPERATION ENABLED"),
    Param("modes_of_operation_display", "int8", Access.R, "", "0x6061 mode the drive runs in"),
    Param("target_torque", "int16", Access.RW, "0.1 %", "0x6071 PT/CST target, per mille of rated torque "
          "(eRunner's panel labels the field mN*m)"),
    Param("torque_actual_value", "int16", Access.R, "0.1 %", "0x6077 actual torque, per mille of rated torque"),
    Param("quick_stop_deceleration", "uint32", Access.RW, "count/s^2", "0x6085 deceleration of a quick stop"),
    Param("software_position_limit_highest_subindex", "uint8", Access.R, "", "0x607D:00 entries", default=2),
    Param("interpolation_sub_mode_select", "int16", Access.RW, "", "0x60C0 IP sub-mode (0 = linear)"),
    Param("interpolation_data_record_highest_subindex", "uint8", Access.R, "", "0x60C1:00 entries", default=1),
    Param("interpolation_data_record_1", "int32", Access.RW, "count", "0x60C1:01 IP position set-point"),
    Param("interpolation_time_period_highest_subindex", "uint8", Access.R, "", "0x60C2:00 entries", default=2),
    Param("interpolation_time_period_value", "uint8", Access.RW, "", "0x60C2:01 IP period = value x 10^index s",
          default=1),
    Param("interpolation_time_index", "int8", Access.RW, "", "0x60C2:02 IP period exponent (-3 = ms)",
          minimum=-128, maximum=63, default=-3),
    Param("supported_drive_modes", "uint32", Access.R, "", "0x6502 modes the drive offers (bit 0 PP, 2 PV, 3 PT, "
          "6 IP, 7 CSP, 8 CSV, 9 CST)", default=0x000003CD),
    # --- end CANopen ---
)

EROB_PARAMS: ParamSet = EROB_MODBUS.params.extended(OTHER_PROTOCOLS)
