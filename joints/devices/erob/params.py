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
