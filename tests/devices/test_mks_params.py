"""MKS parameters and their two protocol maps: invariants, agreement, completeness against the manual."""

from __future__ import annotations

import dataclasses
import re

import pytest

from joints.codecs import mks as codec
from joints.devices.mks import native, state
from joints.devices.mks.modbus import (
    FC_READ,
    FC_WRITE_MULTIPLE,
    FC_WRITE_SINGLE,
    MKS_MODBUS,
    MKS_MODBUS_OF,
    NATIVE_ONLY,
)
from joints.devices.mks.native import MKS_NATIVE, REPLY_RULES, Command, NativeKey
from joints.devices.mks.params import DANGEROUS, FEATURE_OF, MKS_PARAMS, model_params
from joints.devices.params import TYPES, Access
from joints.errors import CommandError, RegisterError
from testdata import manual

MANUAL = manual("mks-servo42d-57d-rs485-manual-v1.0.5.txt")
PARTS_5_6 = MANUAL[MANUAL.index("Part5. Serial command description"):MANUAL.index("Part7. Serial example")]
PART_8 = MANUAL[MANUAL.index("Part8. MODBUS-RTU command description"):MANUAL.index("Part9. FAQ")]
#: what V1.0.9 added (manuals V1.0.9: 0x40 read version 5.1.11 / 3.1.8, 0x98 heartbeat 5.2.16 / 3.2.14)
LATER = {0x40, 0x98, 0x46, 0x47, 0x48, 0x01, 0x35,
         0x36, 0x9D, 0x95, 0x4A, 0x4B, 0x50, 0x96, 0x97, 0x00, 0x42, 0x99, 0x9F}  # V1.0.6-V1.0.9 commands: tests/codecs/test_mks_v109_commands.py


# ------------------------------------------------------------------------------ parameters


def test_names_are_unique_snake_case_identifiers() -> None:
    names = MKS_PARAMS.names()
    assert len(names) == len(set(names)) == 64 + len(FEATURE_OF)
    for n in names:
        assert re.fullmatch(r"[a-z0-9]+(_[a-z0-9]+)*", n), n


def test_bounds_fit_the_types_and_defaults_fit_the_bounds() -> None:
    for p in MKS_PARAMS:
        lo, hi = p.type_range
        assert p.description, p.name
        if p.minimum is not None:
            assert lo <= p.minimum, p.name
        if p.maximum is not None:
            assert p.maximum <= hi, p.name
        if p.access is Access.COMMAND and p.type == "bool":
            assert (p.minimum, p.maximum) == (1, 1), p.name  # commands without data: write 1
        elif p.name != "group_address" and p.access is not Access.R and p.default:
            p.check(p.default)


def test_dangerous_commands_are_persistent() -> None:
    assert DANGEROUS == {
        "calibrate",  # 0x80
        "baud_rate", "slave_address",  # 0x8A, 0x8B
        "modbus_rtu",  # 0x8E
        "zero_mode", "zero_mode_set_zero", "zero_mode_speed", "zero_mode_direction",  # 0x9A
        "save_clean_speed_mode_parameter",  # 0xFF
        "restore_default_parameters", "restart_motor",  # 0x3F, 0x41
        "set_current_axis_to_zero",  # 0x92
        "en_trigger_zero_return",  # 0x9D g0Enable (V1.0.6): the motor moves on an En pulse
        "iap_control",  # 0x50 (V1.0.8): boot loader, silent state
        *(f"{m}_{k}" for m in ("vfoc", "close") for k in ("kp", "ki", "kd", "kv")),  # 0x96 / 0x97 PID (V1.0.8)
        "in1_port_mode",  # 0x9F (V1.0.9): IN_1 as an output reads no home / limit switch
    }
    commands = {MKS_NATIVE.key(n).command for n in DANGEROUS}
    assert commands == {0x80, 0x8A, 0x8B, 0x8E, 0x9A, 0xFF, 0x3F, 0x41, 0x92, 0x9D, 0x50, 0x96, 0x97, 0x9F}


def test_documented_defaults_and_ranges() -> None:
    p = MKS_PARAMS
    assert p["work_mode"].default == state.WorkMode.CR_vFOC
    assert p["microsteps"].default == 16 and (p["microsteps"].minimum, p["microsteps"].maximum) == (1, 256)
    assert p["holding_current"].default == 4 and state.holding_current_percent(4) == 50
    assert p["baud_rate"].default == state.BaudRate.B38400 and state.BaudRate.B38400.bps == 38400
    assert p["en_active_level"].default == state.EnActiveLevel.LOW
    assert p["subdivision_interpolation"].default == 1 and p["locked_rotor_protection"].default == 0
    assert p["slave_respond"].default == 1 and p["slave_active"].default == 1
    assert p["home_reverse_angle"].default == 0x2000
    assert p["encoder_addition"].type == "int48" and p["number_of_pulses"].type == "int32"
    with pytest.raises(CommandError):
        p["speed_mode_speed"].check(3001)
    with pytest.raises(CommandError):
        p["save_clean_speed_mode_parameter"].check(0xC7)
    readable = {x.name for x in p if x.access is Access.R}
    assert readable == {"encoder_carry", "encoder_value", "encoder_addition", "real_time_speed", "number_of_pulses",
                        "io_status", "angle_error", "en_pin_status", "go_back_to_zero_status", "protection_state",
                        "motor_status", "version_information", "raw_encoder_value",
                        "homing_status"}  # 0x3B status2 (V1.0.7)
    assert p["heartbeat_protection_time"].default == 0  # "Default: 0" (off), V1.0.9 5.2.16
    # the MKS reports no setting back, but for the user ID (0x42, V1.0.9: read without data, written with it)
    assert {x.name for x in p if x.access is Access.RW} == {"user_id"}


def test_model_params_keep_the_names_and_narrow_the_currents() -> None:
    d42, d57 = model_params("mks-servo42d"), model_params("mks-servo57d")
    assert d42.names() == d57.names() == MKS_PARAMS.names()
    assert (d42["working_current"].maximum, d42["working_current"].default) == (3000, 1600)
    assert (d57["working_current"].maximum, d57["working_current"].default) == (5200, 3200)
    assert (d42["home_current"].default, d57["home_current"].default) == (800, 400)
    with pytest.raises(CommandError):
        d42["working_current"].check(3200)
    d57["working_current"].check(5200)
    with pytest.raises(ValueError):
        model_params("mks-servo28d")


# ------------------------------------------------------------------------------ native map


def test_native_map_covers_every_parameter_with_unique_keys() -> None:
    assert set(MKS_NATIVE) == set(MKS_PARAMS.names())
    keys = [MKS_NATIVE.key(n) for n in MKS_NATIVE]
    assert len(keys) == len(set(keys))
    for name in MKS_NATIVE:
        assert MKS_NATIVE.name_of(MKS_NATIVE.key(name)) == name


def test_native_fields_are_fields_of_the_codec_messages() -> None:
    for name in MKS_NATIVE:
        key = MKS_NATIVE.key(name)
        param = MKS_PARAMS[name]
        cls = codec.REPLY_TYPES[key.command] if param.access is Access.R else codec.REQUEST_TYPES[key.command]
        fields = [f.name for f in dataclasses.fields(cls) if f.name not in ("address", "function")]
        if key.field:
            assert key.field in fields, (name, cls.__name__)
        else:  # a command without data (a later firmware's optional field aside: 0x91's goZeroMode)
            optional = {MKS_NATIVE.key(n).field for n in native.fields_of(key.command) if n in native.OPTIONAL_FIELDS}
            assert set(fields) == optional, (name, cls.__name__)
    # every data field of every request is some parameter (a driver can build each command)
    for code, cls in codec.REQUEST_TYPES.items():
        for f in dataclasses.fields(cls):
            if f.name != "address" and code not in native.BLOCK_COMMANDS:
                assert NativeKey(Command(code), f.name) in {MKS_NATIVE.key(n) for n in MKS_NATIVE}, (cls, f.name)


def test_command_enum_matches_the_codec() -> None:
    assert {int(c) for c in Command} == set(codec.REQUEST_TYPES)
    assert set(REPLY_RULES) == set(Command)
    assert native.LONG_PACKET == codec.HEAD_LONG and native.BROADCAST == codec.BROADCAST
    assert native.fields_of(Command.SET_HOME_PARAMETERS) == ("home_trigger_level", "home_direction", "home_speed",
                                                             "end_limit")


def test_every_command_of_parts_5_and_6_is_in_the_manual_and_the_map() -> None:
    """Collect every downlink function code the manual prints (tables "| FA | 01 | 80 |" and lines
    "FA 01 30 CRC") and compare with the Command enum."""
    codes = {int(c, 16) for c in re.findall(r"\|\s*FA\s*\|\s*(?:01|addr)\s*\|\s*([0-9A-F]{2})\s*\|", PARTS_5_6)}
    codes |= {int(c, 16) for c in re.findall(r"FA 01 ([0-9A-F]{2}) CRC", PARTS_5_6)}
    assert codes == {int(c) for c in Command} - LATER
    assert {int(MKS_NATIVE.key(n).command) for n in FEATURE_OF
            if n not in native.OPTIONAL_FIELDS and n != "homing_status"} \
        | set(native.BLOCK_COMMANDS) == LATER  # (optional fields and 0x3B's second status: longer forms)
    assert "| Head | 0xFC |" in PARTS_5_6  # the long data package head
    used = {MKS_NATIVE.key(n).command for n in MKS_NATIVE}
    assert used == set(Command) - native.BLOCK_COMMANDS  # the blocks carry many (joints.devices.mks.blocks)


def test_reply_rules_follow_the_manual() -> None:
    for c in native.RUN_COMMANDS:
        assert REPLY_RULES[c].silenced_by_respond_off and REPLY_RULES[c].completion_needs_active
    assert not native.expects_reply(Command.POSITION_MODE1_RELATIVE_PULSES, 0)  # broadcast
    assert not native.expects_reply(Command.POSITION_MODE1_RELATIVE_PULSES, 0x50, groups={0x50})  # group
    assert native.expects_reply(Command.POSITION_MODE1_RELATIVE_PULSES, 1)
    assert not native.expects_reply(Command.SPEED_MODE, 1, respond=False)  # 0x8C respond off
    assert native.expects_reply(Command.READ_ENCODER_VALUE_ADDITION, 1, respond=False)  # queries still answer
    assert not native.expects_reply(0x51, 1)  # unknown code (0x50 is IAP from V1.0.8)
    assert native.expects_completion(Command.POSITION_MODE4_ABSOLUTE_AXIS, 1)
    assert not native.expects_completion(Command.POSITION_MODE4_ABSOLUTE_AXIS, 1, active=False)
    assert not native.expects_completion(Command.POSITION_MODE4_ABSOLUTE_AXIS, 1, respond=False)
    assert not native.expects_completion(Command.SET_WORK_MODE, 1)
    assert native.expects_completion(Command.CALIBRATE_ENCODER, 1, active=False)


# ------------------------------------------------------------------------------ Modbus map


def test_every_modbus_field_is_a_parameter_of_the_same_type_and_access() -> None:
    # 0x35, 0x95 (2 fields), 0x4A, 0x42, 0x9F: native only (0x3B status2 and FC16 0x0094's three: in the newest map)
    assert len(MKS_MODBUS) == 58 + 3 + len(FEATURE_OF) - 6
    for f in MKS_MODBUS:
        p = MKS_PARAMS[f.name]
        assert (f.type, f.access) == (p.type, p.access), f.name
        assert TYPES[f.type][2] <= f.size or f.size == 0  # (0: implied by the request, 0x91's go_home)
        if f.maximum is not None:  # narrower over Modbus only
            assert p.maximum is None or f.maximum <= p.maximum
    assert MKS_MODBUS.get("slave_address").maximum == 247


def test_modbus_and_native_reach_the_same_command() -> None:
    """Part 8 uses the native function code as the register address."""
    for f in MKS_MODBUS:
        assert f.address == MKS_NATIVE.key(f.name).command, f.name
        expected_fc = FC_READ if MKS_PARAMS[f.name].access is Access.R else None
        if expected_fc:
            assert f.function == expected_fc
    assert NATIVE_ONLY == {"slave_respond", "slave_active", "group_address",  # (0x94: FC16 0x0094 from V1.0.6)
                           "raw_encoder_value",  # 0x35: not in the Modbus-RTU manual V1.0.9
                           "position_threshold_enable", "position_threshold", "sync_enable",  # 0x95, 0x4A: neither
                           "user_id",  # 0x42: not in the Modbus-RTU manual V1.0.9
                           "in1_port_mode"}  # 0x9F: neither
    assert set(MKS_MODBUS.names()) | NATIVE_ONLY == set(MKS_PARAMS.names())


def test_modbus_map_is_a_param_map() -> None:
    m = MKS_MODBUS.as_map()
    assert m.protocol == "modbus-rtu" and set(m) == set(MKS_MODBUS.names())
    assert m.key("working_current").address == 0x83
    with pytest.raises(RegisterError, match="cannot be reached over modbus-rtu"):
        m.key("group_address")
    with pytest.raises(RegisterError, match="Modbus"):
        MKS_MODBUS.get("slave_respond")
    assert set(MKS_MODBUS.params.names()) == set(MKS_MODBUS.names())


def test_every_modbus_request_of_part_8_is_in_the_table() -> None:
    found = set(re.findall(r"\|\s*01H\s*\|\s*(04|06|10)\s*H\s*\|\s*00H\s*\|\s*([0-9A-F]{2})H\s*\|", PART_8))
    blocks = {(int(fc, 16), int(a, 16)) for fc, a in found}
    assert blocks == {(b.function, b.address) for b in MKS_MODBUS_OF["v1.0.5"].blocks if b.address not in LATER}
    # V1.0.9 Modbus manual: 3.1.8 "01H 04H 00H 40H 00H 02H 70H 1FH", 3.2.14 FC10 0x0098 2 registers 4 bytes
    assert (MKS_MODBUS.block(FC_READ, 0x40).count, MKS_MODBUS.block(FC_WRITE_MULTIPLE, 0x98).count) == (2, 2)
    # register counts as printed ("| 00H | count |" after the address) for FC04 and FC16 requests
    for fc, a, count in re.findall(r"\|\s*01H\s*\|\s*(04|10)\s*H\s*\|\s*00H\s*\|\s*([0-9A-F]{2})H\s*\|\s*00H\s*\|"
                                   r"\s*([0-9A-F]{2})H", PART_8):
        assert MKS_MODBUS.block(int(fc, 16), int(a, 16)).count == int(count, 16), (fc, a)
    assert "| 00H | 03H | 05H |" in PART_8  # the 0x90 quirk as printed


def test_blocks_encode_and_decode_their_fields() -> None:
    fd = MKS_MODBUS.block(FC_WRITE_MULTIPLE, 0xFD)
    values = {"position_mode1_direction": 1, "position_mode1_acc": 2, "position_mode1_speed": 600,
              "position_mode1_pulses": 3200}
    assert fd.words(values) == (0x0102, 600, 0, 3200)
    assert fd.decode_words(fd.words(values)) == values
    fe = MKS_MODBUS.block(FC_WRITE_MULTIPLE, 0xFE)
    words = fe.words({"position_mode2_acc": 2, "position_mode2_speed": 600, "position_mode2_abs_pulses": -0x4000})
    assert words == (2, 600, 0xFFFF, 0xC000)
    carry = MKS_MODBUS.block(FC_READ, 0x30)
    assert carry.decode_words((0xFFFF, 0xFFFF, 0x2269)) == {"encoder_carry": -1, "encoder_value": 0x2269}
    add = MKS_MODBUS.block(FC_READ, 0x31)
    assert add.decode_words((0xFFFF, 0xFFFF, 0xFFF0)) == {"encoder_addition": -16}
    io = MKS_MODBUS.block(FC_READ, 0x34)
    assert io.decode_words((0x0005,)) == {"io_status": 5}
    single = MKS_MODBUS.block(FC_WRITE_SINGLE, 0x84)
    assert single.words({"microsteps": 256}) == (256,)
    with pytest.raises(CommandError):
        fd.words({"position_mode1_direction": 1})  # every field of the command is needed
    with pytest.raises(CommandError):
        MKS_MODBUS.block(FC_WRITE_SINGLE, 0x8B).words({"slave_address": 248})
    with pytest.raises(RegisterError):
        MKS_MODBUS.block(FC_READ, 0x82)
    assert MKS_MODBUS.block_of("speed_mode_acc").address == 0xF6
