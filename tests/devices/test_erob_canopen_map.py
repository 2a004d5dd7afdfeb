"""eRob CANopen object dictionary: map invariants, EDS completeness, eRunner PDOs, chapter-5 cross-checks."""

from __future__ import annotations

import re

import pytest

from joints.devices import cia402
from joints.devices.cia402 import Mode, State
from joints.devices.erob import canopen as eco
from joints.devices.erob.canopen import (
    EROB_CANOPEN,
    ERUNNER_RPDO1,
    ERUNNER_TPDOS,
    OBJECT_NAMES,
    SUPPORTED_MODES,
    TARGET_PARAM,
    CanopenObject,
    DataType,
    ObjectAccess,
    PdoConfig,
    name_at,
    objects,
)
from joints.devices.erob.params import EROB_PARAMS, OTHER_PROTOCOLS
from joints.devices.erob.registers import EROB_MODBUS
from joints.devices.params import TYPES
from joints.errors import CommandError, FrameError, RegisterError
from testdata import manual, vectors

CHAPTER5 = manual("erob-erunner-can-canopen-manual-v1.7-zh.txt").split("5. CANopen 协议控制")[2].split(
    "6. 自定义数据收发")[0]
MANUAL = manual("erob-erunner-can-canopen-manual-v1.7-zh.txt")

#: Modbus register names CANopen reaches as the same quantity (a deliberate, reviewed list)
SHARED = {
    "error_code", "given_position", "actual_position", "max_position_error", "position_reaches_set_precision",
    "time_setting_of_achieving_position", "given_speed", "current_speed", "motor_current", "bus_voltage",
    "target_absolute_position", "min_position_limit_value", "max_position_limit_value", "profile_speed",
    "profile_acceleration", "profile_deceleration", "position_error", "target_speed", "max_speed",
    "part_of_power_temperature",  # 0x22A2 drive temperature = Modbus 0x0078 (E11)
}
CANOPEN_ONLY = {p.name for p in OTHER_PROTOCOLS if re.match(r"0x[0-9A-F]{4}", p.description)}


# ---------------------------------------------------------------------------- invariants


def test_addresses_are_unique_and_every_name_is_a_parameter() -> None:
    addresses = [(o.index, o.subindex) for _n, o in objects()]
    assert len(addresses) == len(set(addresses)) == len(EROB_CANOPEN)
    for name in EROB_CANOPEN:
        assert name in EROB_PARAMS
        assert name_at(EROB_CANOPEN.key(name).index, EROB_CANOPEN.key(name).subindex) == name


def test_shared_names_are_the_modbus_quantities() -> None:
    shared = {n for n in EROB_CANOPEN if n in EROB_MODBUS}
    assert shared == SHARED
    # the CAN custom protocol's analog input is ZeroErr's 0x2205
    assert {n for n in EROB_CANOPEN if n not in EROB_MODBUS} == CANOPEN_ONLY | {"analog_input"}
    # the Modbus mode codes (1 torque, 2 speed, 3 position) are not CiA 402 codes: no shared name
    with pytest.raises(RegisterError, match="cannot be reached over canopen"):
        EROB_CANOPEN.key("operation_mode")


@pytest.mark.parametrize("name", sorted(EROB_CANOPEN))
def test_object_matches_its_parameter(name: str) -> None:
    obj, param = EROB_CANOPEN.key(name), EROB_PARAMS[name]
    assert isinstance(obj.datatype, DataType) and isinstance(obj.access, ObjectAccess)
    assert obj.access.readable == param.access.readable
    assert obj.access.writable == param.access.writable
    assert obj.size == TYPES[obj.datatype.param_type][2]
    lo, hi = TYPES[obj.datatype.param_type][:2]
    assert lo <= obj.default(1) and obj.default(127) <= hi  # the EDS default fits the type
    if name in CANOPEN_ONLY and name != "analog_input":
        assert param.type == obj.datatype.param_type
        assert param.description.startswith(f"0x{obj.index:04X}")
        if obj.subindex or obj.index in OBJECT_NAMES:
            assert f"0x{obj.index:04X}:{obj.subindex:02X}" in param.description
        assert obj.scale == 1.0 and not obj.unit
    else:  # a Modbus quantity: same unit unless the object says otherwise
        assert (obj.scale == 1.0) == (not obj.unit)
    if obj.pdo_mappable:
        assert obj.bits <= 32


def test_scale_of_the_position_window_time() -> None:
    obj = EROB_CANOPEN.key("time_setting_of_achieving_position")
    assert (obj.index, obj.unit, obj.scale) == (0x6068, "ms", 20.0)
    assert EROB_PARAMS["time_setting_of_achieving_position"].unit == "0.05 ms"  # Modbus 0x007A


def test_records_have_their_subindex_zero() -> None:
    by_index: dict[int, list[CanopenObject]] = {}
    for _n, o in objects():
        by_index.setdefault(o.index, []).append(o)
    for index, entries in by_index.items():
        subs = sorted(o.subindex for o in entries)
        if index in OBJECT_NAMES:
            assert subs[0] == 0, hex(index)
            sub0 = EROB_PARAMS[name_at(index, 0)].default
            if 0x1600 <= index <= 0x17FF or 0x1A00 <= index <= 0x1BFF:
                assert subs == list(range(9)) and sub0 <= 8  # mapping: sub 0 = number of mapped objects
            elif index == 0x1003:
                assert sub0 == 0 and subs[-1] == 4  # pre-defined error field: sub 0 = number of errors
            else:
                assert sub0 == subs[-1], hex(index)  # highest sub-index supported
        else:
            assert subs == [0], hex(index)


def test_cob_ids_are_node_relative() -> None:
    relative = {n for n, o in objects() if o.node_relative}
    sdo = {"server_sdo_parameter_cob_id_client_to_server_receive_sdo",
           "server_sdo_parameter_cob_id_server_to_client_transmit_sdo"}
    assert relative == {"cob_id_emcy"} | sdo | {f"{k}{i}_cob_id" for k in ("rpdo", "tpdo") for i in range(1, 5)}
    assert EROB_CANOPEN.key("rpdo1_cob_id").default(2) == 0x202
    assert EROB_CANOPEN.key("tpdo4_cob_id").default(2) == 0x80000482
    assert EROB_CANOPEN.key("cob_id_emcy").default(5) == 0x85
    assert EROB_CANOPEN.key("cob_id_sync").default(5) == 0x80
    assert EROB_CANOPEN.key("rpdo2_cob_id").default(2) == 0x80000302  # not valid at power-on (the EDS)


def test_encode_decode_values() -> None:
    assert EROB_CANOPEN.key("profile_speed").encode(5566) == bytes.fromhex("BE 15 00 00")
    assert EROB_CANOPEN.key("modes_of_operation").encode(-1) == b"\xff"
    assert EROB_CANOPEN.key("target_speed").decode(bytes.fromhex("42 EA FF FF")) == -5566
    assert EROB_CANOPEN.key("statusword").decode(bytes.fromhex("37 16")) == 0x1637
    with pytest.raises(CommandError):
        EROB_CANOPEN.key("profile_speed").encode(-1)  # UNSIGNED32 on CANopen (int32 on Modbus)
    with pytest.raises(CommandError):
        EROB_CANOPEN.key("modes_of_operation").encode(128)
    with pytest.raises(FrameError):
        EROB_CANOPEN.key("statusword").decode(b"\x37")
    with pytest.raises(RegisterError):
        name_at(0x6073, 0)  # not in ZeroErr's EDS
    assert eco.has_index(0x1600) and eco.has_index(0x6099) and not eco.has_index(0x6073)


def test_objects_are_equal_by_address() -> None:
    a = EROB_CANOPEN.key("controlword")
    b = CanopenObject(0x6040, 0, DataType.UNSIGNED16, ObjectAccess.RO, "x")
    assert a == b and hash(a) == hash(b) and a != EROB_CANOPEN.key("statusword")
    assert "0x6040:00" in repr(a)


# ---------------------------------------------------------------------------- PDOs


@pytest.mark.parametrize("kind", ["RPDO", "TPDO"])
@pytest.mark.parametrize("number", [1, 2, 3, 4])
def test_power_on_mapping_is_zeroerrs(kind: str, number: int) -> None:
    """ZeroErr's EDS: PDO1 control/statusword alone, PDO2 + position, PDO3 + velocity, PDO4 empty."""
    pdo = eco.power_on_pdo(kind, number)
    first = "controlword" if kind == "RPDO" else "statusword"
    second = {"RPDO": (None, "target_absolute_position", "target_speed"),
              "TPDO": (None, "actual_position", "current_speed")}[kind][number - 1] if number < 4 else None
    expected = () if number == 4 else (first,) if second is None else (first, second)
    assert pdo.objects == expected
    for name in pdo.objects:
        assert isinstance(name, str) and EROB_CANOPEN.key(name).pdo_mappable
    assert pdo.cob_id(3) == {"RPDO": 0x100, "TPDO": 0x80}[kind] + 0x100 * number + 3


@pytest.mark.parametrize("mode", sorted(ERUNNER_RPDO1))
def test_erunner_rpdo1_is_controlword_and_a_32_bit_target(mode: Mode) -> None:
    pdo = ERUNNER_RPDO1[mode]
    assert (pdo.kind, pdo.number, pdo.size) == ("RPDO", 1, 6)
    assert pdo.objects[:2] == ("controlword", TARGET_PARAM[mode])
    assert pdo.entries[0] == (0x6040, 0, 16, False)
    assert pdo.transmission_type == (1 if mode.cyclic else 255)
    assert pdo.communication_index == 0x1400 and pdo.mapping_index == 0x1600
    for name in pdo.objects:
        if isinstance(name, str):
            assert EROB_CANOPEN.key(name).pdo_mappable and EROB_CANOPEN.key(name).access.writable
    if mode in (Mode.PT, Mode.CST):
        assert pdo.entries[2] == (0x0006, 0, 16, False)  # UNSIGNED16 dummy (E2)


def test_erunner_tpdos() -> None:
    assert [p.objects for p in ERUNNER_TPDOS] == [("statusword", "actual_position"), ("current_speed", "motor_current")]
    assert all(p.size == 6 and p.transmission_type == 1 for p in ERUNNER_TPDOS)
    assert [p.cob_id(2) for p in ERUNNER_TPDOS] == [0x182, 0x282]
    with pytest.raises(ValueError):
        PdoConfig("TPDO", 5, ("statusword",))
    with pytest.raises(ValueError):
        PdoConfig("TPDO", 1, ("actual_position",) * 3)


# ---------------------------------------------------------------------------- modes


def test_supported_modes_are_the_chapter5_modes() -> None:
    titles = ["轮廓位置模式", "轮廓速度模式", "轮廓扭矩模式", "周期同步位置模式", "周期同步速度模式", "周期同步扭矩模式",
              "位置插补模式"]
    for title in titles:
        assert title in CHAPTER5
    written = {v["decoded"]["value"] for v in vectors("canopen", "erob")
               if v["decoded"].get("index") == "0x6060" and "value" in v["decoded"]}
    assert {Mode(m) for m in written} == SUPPORTED_MODES
    assert len(titles) == len(SUPPORTED_MODES) and Mode.HM not in SUPPORTED_MODES
    assert EROB_PARAMS["supported_drive_modes"].default == cia402.supported_modes_bits(SUPPORTED_MODES) == 0x3CD
    assert set(TARGET_PARAM) == SUPPORTED_MODES


def test_mode_change_only_out_of_operation_enabled() -> None:
    assert "每次切换运动模式之前都需要先下使能" in CHAPTER5
    assert not eco.mode_change_allowed(State.OPERATION_ENABLED)
    assert all(eco.mode_change_allowed(s) for s in State if s is not State.OPERATION_ENABLED)
    assert eco.MODE_CHANGE_REFUSED == 0x08000022


# ---------------------------------------------------------------------------- chapter-5 text


@pytest.mark.parametrize("frame,name,value", [
    ("2F 60 60 00 01 00 00 00", "modes_of_operation", 1),
    ("4F 61 60 00 0A 00 00 00", "modes_of_operation_display", 10),
    ("23 81 60 00 BE 15 00 00", "profile_speed", 5566),
    ("23 83 60 00 BE 15 00 00", "profile_acceleration", 5566),
    ("23 84 60 00 BE 15 00 00", "profile_deceleration", 5566),
    ("23 FF 60 00 00 00 00 00", "target_speed", 0),
    ("23 05 10 00 80 00 00 00", "cob_id_sync", 0x80),
    ("23 06 10 00 E8 03 00 00", "communication_cycle_period", 1000),
])
def test_chapter5_sdo_frames_fit_the_map(frame: str, name: str, value: int) -> None:
    assert frame in CHAPTER5
    data = bytes.fromhex(frame)
    obj = EROB_CANOPEN.key(name)
    assert (data[1] | data[2] << 8, data[3]) == (obj.index, obj.subindex)
    size = 4 - (data[0] >> 2 & 3)
    assert size == obj.size
    assert obj.decode(data[4:4 + size]) == value
    assert obj.encode(value) == data[4:4 + size]


def test_chapter5_units_and_defaults() -> None:
    assert "设置速度为5566cnt/s" in CHAPTER5 and EROB_PARAMS["profile_speed"].unit == "count/s"
    assert "设置加速度为5566cnt/s" in CHAPTER5 and EROB_PARAMS["profile_acceleration"].unit == "count/s^2"
    assert "Set communication cycle period(µs)" in CHAPTER5
    assert EROB_PARAMS["communication_cycle_period"].unit == "us"
    # eRunner's connection setting is 1000 us (what eRunner writes); the power-on value is the EDS's 0
    assert re.search(r"默认设置为1000 ?µ ?s", MANUAL) and EROB_PARAMS["communication_cycle_period"].default == 0
    assert "关闭同步发生器 Disable cob-id sync" in CHAPTER5 and EROB_PARAMS["cob_id_sync"].default == 0x80
    assert "电机电流" in CHAPTER5 and "mA" in CHAPTER5 and EROB_PARAMS["motor_current"].unit == "mA"
    assert "mN · m" in CHAPTER5 or "mN·m" in CHAPTER5  # E2: the torque panel's label
    assert "0.1 %" == EROB_PARAMS["target_torque"].unit
    # RPDO1 frames of chapter 5 are 6 bytes: controlword + 32-bit slot
    for rpdo in ("1F 00 00 00 00 00", "06 00 00 00 00 00", "2F 00 28 00 00 00", "2F 00 68 F3 21 00",
                 "2F 00 BE 15 00 00"):
        assert rpdo in CHAPTER5 and len(bytes.fromhex(rpdo)) == ERUNNER_RPDO1[Mode.PP].size
