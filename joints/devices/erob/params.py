"""The eRob's parameters, defined once for every protocol that reaches the drive.

Rule: the Modbus manual's chapter-4 table (:data:`joints.devices.erob.registers.EROB_MODBUS`) is
the base: each of its registers is one parameter by the same name. Quantities that only the CAN
custom protocol or CANopen reach are added here as :class:`~joints.devices.params.Param` entries,
so every protocol map (Modbus register, CAN index, CANopen object) names the same quantities.
"""

from __future__ import annotations

from joints.devices.canopen import DataType
from joints.devices.erob import od
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
)
_TAKEN = frozenset(p.name for p in (*EROB_MODBUS.params, *OTHER_PROTOCOLS)) - od.BOUND
#: the CANopen objects (ZeroErr's EDS + deviations), named (joints.devices.erob.od)
CANOPEN_ENTRIES = od.entries(_TAKEN)
OTHER_PROTOCOLS = (
    *OTHER_PROTOCOLS,
    # --- CANopen: every object of ZeroErr's EDS the Modbus table does not name (joints.devices.erob.od) ---
    *(Param(e.name, DataType(e.datatype).param_type, Access.R if e.access in ("ro", "const") else Access.RW,
            od.unit(e.name), f"0x{e.index:04X}:{e.subindex:02X} {e.object_name}"
            + (f": {e.entry_name}" if e.object_type != 7 else "") + " (CANopen)",
            maximum=8 if e.name.endswith("_mapped_objects") else None,
            default=e.default or 0)
      for e in CANOPEN_ENTRIES if e.name not in EROB_MODBUS.params and e.name not in _TAKEN | {"analog_input"}),
)

EROB_PARAMS: ParamSet = EROB_MODBUS.params.extended(OTHER_PROTOCOLS)
