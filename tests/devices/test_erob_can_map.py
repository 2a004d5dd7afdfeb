"""eRob CAN custom-protocol map: invariants, every entry against the manual's 7.5 tables, names
shared with the Modbus table, error-reply codes of appendix 1, module information of 7.5.3."""

from __future__ import annotations

import re
from typing import Any

import pytest

from joints.codecs import erob_can as ec
from joints.devices.erob import can as ecan
from joints.devices.erob.can import EROB_CAN, CanIndex, ModuleConfig, ModuleInfo, Reach
from joints.devices.erob.faults import FAULTS
from joints.devices.erob.params import EROB_PARAMS, OTHER_PROTOCOLS
from joints.devices.erob.registers import EROB_MODBUS, AchieveStatus, MotionMode, OperationMode
from joints.devices.params import Access
from joints.errors import CommandError, RegisterError
from testdata import manual, vectors

MANUAL = manual("erob-erunner-can-canopen-manual-v1.7-zh.txt").splitlines()

# ------------------------------------------------------------------------------ the manual's tables

#: OCR look-alikes in the tables (Cyrillic letters in hex indexes, a Japanese kanji, '忌' for '总' in 0x0124)
_OCR_CHARS = str.maketrans({"А": "A", "В": "B", "С": "C", "Е": "E", "単": "单", "忌": "总"})
#: index cells the OCR misread ("222" for "232" in two rows of 0x0232) and subindex cells ("/" for 7)
_INDEX_ALIAS = {"222": "232"}
_SUB_ALIAS = {"/": "7"}
#: access cells as printed, OCR damage included (rows 0x0112, 0x0204 print 'DW', 'Γ.vv', 'ĸw' for RW;
#: 0x0232/2 and /7 'DO' for RO); 0x0114 prints '-' (a write of 1 that triggers an action)
_ACCESS = {"RO": Access.R, "RW": Access.RW, "W": Access.COMMAND, "DW": Access.RW, "Γ.vv": Access.RW,
           "ĸw": Access.RW, "DO": Access.R, "-": Access.COMMAND}
_UNITS = {"count": "count", "count/s": "count/s", "count/s ²": "count/s^2", "mA": "mA", "mV": "mV", "ms": "ms",
          "°C": "degC", "bps": "bps", "mNm": "mNm", "0.10%": "0.1%", "-": "",
          "RO -": ""}  # 0x0232/2: the access column repeated into the unit cell
#: units printed otherwise than the map says, with the reason
_UNIT_EXCEPTIONS = {0x000D: "mA printed for mV (ERRATA DOC-EROB-CAN-3)", 0x008B: "'us' printed: a time code"}
#: rows whose definition cell the OCR lost or garbled: the fragment printed instead
_DEFINITION_OCR = {(0x0112, None): "", (0x020D, None): "", (0x0232, 5): "快"}


def _norm(text: str) -> str:
    return re.sub(r"\s+", "", text.translate(_OCR_CHARS))


def _section(start: str, end: str) -> tuple[int, int]:
    """Line range of a body section (the table of contents has the same headings, tab-separated)."""
    lo = next(i for i, line in enumerate(MANUAL) if line.startswith(start + " "))
    hi = next(i for i, line in enumerate(MANUAL) if i > lo and line.startswith(end + " "))
    return lo, hi


def _rows(lo: int, hi: int) -> dict[str, list[tuple[int, list[str]]]]:
    """Table rows by index cell (hex, normalised): (line number, cells)."""
    rows: dict[str, list[tuple[int, list[str]]]] = {}
    for i in range(lo, hi):
        cells = MANUAL[i].split("\t")
        idx = cells[0].strip().translate(_OCR_CHARS)
        idx = _INDEX_ALIAS.get(idx, idx)
        if len(cells) >= 4 and re.fullmatch(r"[0-9A-F]{1,3}", idx):
            rows.setdefault(idx, []).append((i, [c.strip() for c in cells]))
    return rows


T751 = _rows(*_section("7.5.1", "7.5.2"))
T752 = _rows(*_section("7.5.2", "7.5.3"))


def _entry_rows(key: CanIndex) -> list[tuple[int, list[str]]]:
    table = T752 if key.source == "7.5.2" else T751
    found = []
    for line, cells in table.get(f"{key.index:X}", []):
        sub = _SUB_ALIAS.get(cells[1], cells[1])
        if key.subindex is None and sub in ("-", "_", "") or sub == f"{key.subindex:X}":
            found.append((line, cells))
    return found


IN_TABLES = [(name, key) for name, key in EROB_CAN.keys.items() if key.source in ("7.5.1", "7.5.2")]


# ------------------------------------------------------------------------------------------ invariants


def test_every_name_is_an_erob_parameter_and_keys_are_unique() -> None:
    assert EROB_CAN.params is EROB_PARAMS
    assert EROB_CAN.protocol == "erob-can"
    assert all(name in EROB_PARAMS for name in EROB_CAN)
    addresses = [(k.index, k.subindex) for k in EROB_CAN.keys.values()]
    assert len(set(addresses)) == len(addresses)
    for name, key in EROB_CAN.keys.items():
        assert 0 <= key.index <= 0xFFFF and (key.subindex is None or 0 <= key.subindex <= 0xFFFF)
        assert EROB_CAN.at(key.index, key.subindex) == name
        assert key.definition, name
        assert key.scale >= 1


def test_keys_compare_by_address_only() -> None:
    assert CanIndex(0x58, None, scale=20, unit="ms", note="x") == CanIndex(0x58)
    assert hash(CanIndex(0x232, 1, definition="a")) == hash(CanIndex(0x232, 1))
    assert CanIndex(0x232, 1) != CanIndex(0x232, 2) and CanIndex(0x5) != CanIndex(0x5, 1)
    assert str(CanIndex(0x232, 8)) == "0x0232/8" and str(CanIndex(0x8A)) == "0x008A"


def test_commands_agree_with_the_codec() -> None:
    commands = {k.index: k.reach for k in EROB_CAN.keys.values() if k.reach is not Reach.VALUE}
    assert set(commands) == set(ec.COMMANDS)
    for index, reach in commands.items():
        assert ec.COMMANDS[index] == (reach is Reach.COMMAND_WITH_PARAMETER)
        assert EROB_CAN.keys[EROB_CAN.at(index)].subindex is None
    for name, key in EROB_CAN.keys.items():
        if key.reach is not Reach.VALUE:
            assert EROB_CAN.access(name) is Access.COMMAND, name


def test_names_are_modbus_names_or_can_only_parameters() -> None:
    modbus = set(EROB_MODBUS.names())
    can_only = {p.name for p in OTHER_PROTOCOLS}
    for name in EROB_CAN:
        assert name in modbus or name in can_only, name
    # every CAN-only parameter added by this protocol is mapped (none is dead weight)
    ours = {"hardware_version", "firmware_version", "release_brake", "can_address", "module_serial",
            "analog_quantity_value"}
    assert ours <= set(EROB_CAN)


def test_persistent_and_dangerous_entries_need_confirmation() -> None:
    for name in ("save_parameters", "release_brake", "reset_output_encoder", "can_address", "modbus_address"):
        assert EROB_CAN.param(name).persistent, name
    assert EROB_CAN.key("save_parameters").index == 0xE8
    assert EROB_CAN.key("release_brake").index == 0x14F
    assert EROB_CAN.key("reset_output_encoder").index == 0x114
    assert EROB_CAN.key("can_address").index == 0x43
    for name in ("profile_speed", "target_absolute_position", "enable_the_motor", "start_operating"):
        assert not EROB_CAN.param(name).persistent, name


def test_bitrate_is_read_only() -> None:
    assert EROB_CAN.key("can_baud_rate").index == 0x44
    assert EROB_CAN.access("can_baud_rate") is Access.R
    assert EROB_CAN.param("can_baud_rate").default == 1_000_000


def test_lookup_errors_name_the_protocol() -> None:
    with pytest.raises(RegisterError, match="cannot be reached over erob-can"):
        EROB_CAN.key("emergency_stop")  # Modbus 0x00F3 has no CAN index
    with pytest.raises(RegisterError):
        EROB_CAN.at(0x0BAD)


# ------------------------------------------------------------------------------ against the manual


def test_tables_were_found() -> None:
    assert len(T751) >= 55 and set(T752) == {"83", "84", "E8", "100", "14F"}


@pytest.mark.parametrize(("name", "key"), IN_TABLES, ids=[n for n, _ in IN_TABLES])
def test_entry_matches_the_manual_row(name: str, key: CanIndex) -> None:
    rows = _entry_rows(key)
    assert rows, f"{name}: no row {key} in table {key.source}"
    fragments = [_norm(cells[2]) for _, cells in rows if _norm(cells[2])]
    printed = _DEFINITION_OCR.get((key.index, key.subindex))
    if printed is not None:
        assert "".join(fragments) == printed, fragments
        assert "OCR" in key.note
    else:
        assert fragments
        for fragment in fragments:
            assert fragment in _norm(key.definition), (fragment, key.definition)
    accesses = {_ACCESS[c[3]] for _, c in rows if c[3] in _ACCESS}
    assert accesses == {EROB_CAN.access(name)}, (accesses, rows)
    if key.source == "7.5.2":
        has_parameter = {c[4] for _, c in rows}
        assert has_parameter == {"是" if key.reach is Reach.COMMAND_WITH_PARAMETER else "否"}
        return
    units = {_UNITS[c[4]] for _, c in rows if c[4] in _UNITS}
    if len(units) > 1:  # a continuation row prints '-'
        units.discard("")
    if key.index in _UNIT_EXCEPTIONS:
        assert units != {EROB_CAN.unit(name)}
        assert "ERRATA" in key.note or "code" in key.note
    else:
        assert units == {EROB_CAN.unit(name)}, (units, rows)


def test_every_row_of_the_tables_is_mapped() -> None:
    mapped = {(f"{k.index:X}", k.source == "7.5.2") for k in EROB_CAN.keys.values()}
    for idx in T751:
        assert (idx, False) in mapped, idx
    for idx in T752:
        assert (idx, True) in mapped, idx
    subs = {k.subindex for k in EROB_CAN.keys.values() if k.index == 0x232}
    assert subs == {1, 2, 5, 6, 7, 8}


def _window(key: CanIndex) -> str:
    line = _entry_rows(key)[0][0]
    return _norm(" ".join(MANUAL[line - 3:line + 4]))


@pytest.mark.parametrize(("name", "meanings"), [
    ("operation_mode", {OperationMode.TORQUE: "力矩控制", OperationMode.SPEED: "速度控制",
                        OperationMode.POSITION: "位置控制"}),
    ("motion_mode", {MotionMode.CONTINUOUS: "连续运动模式", MotionMode.ABSOLUTE: "目标位置模式",
                     MotionMode.REPETITIVE: "往返运动模式"}),
    ("status_of_achieving_position", {AchieveStatus.MOTOR_OFF: "电机关闭", AchieveStatus.MOTOR_ON: "电机打开",
                                      AchieveStatus.WAIT_TIME: "等待定位时间",
                                      AchieveStatus.TARGET_REACHED: "标到达"}),  # OCR: '日标到达'
    ("enable_the_motor", {0: "下使能", 1: "上使能"}),
    ("control_source", {0: "使用", 1: "EtherCAT"}),  # OCR: '小使用' for '不使用'
])
def test_shared_enumerations_mean_the_same_values(name: str, meanings: dict[int, str]) -> None:
    text = _window(EROB_CAN.key(name))
    for value, word in meanings.items():
        assert re.search(rf"{int(value)}[:.].?{re.escape(word)}", text), (name, value, word)


#: CAN unit -> Modbus unit -> parameter value per CAN unit
_UNIT_RATIO = {("ms", "0.05 ms"): 20}


def test_names_shared_with_modbus_are_the_same_quantity() -> None:
    shared = [n for n in EROB_CAN if n in EROB_MODBUS]
    assert len(shared) >= 40
    for name in shared:
        key = EROB_CAN.key(name)
        assert EROB_PARAMS[name] == EROB_MODBUS[name].param, name  # one definition
        if key.scale == 1:
            assert key.unit in (None, ""), name
            if key.unit == "":
                assert EROB_PARAMS[name].unit == "", name
        else:
            assert key.unit is not None
            assert _UNIT_RATIO[(key.unit, EROB_PARAMS[name].unit)] == key.scale, name
            assert "Modbus" in key.note, name
    scaled = {n for n in shared if EROB_CAN.key(n).scale != 1}
    assert scaled == {"struck_time", "dwell_time", "time_setting_of_achieving_position"}


def test_brief_names_are_the_modbus_names() -> None:
    expected = {0x004E: "operation_mode", 0x008D: "motion_mode", 0x0100: "enable_the_motor",
                0x0083: "start_operating", 0x0084: "stop_operating", 0x00E8: "save_parameters",
                0x0086: "target_absolute_position", 0x0087: "target_relative_position", 0x008A: "profile_speed",
                0x0088: "profile_acceleration", 0x0089: "profile_deceleration", 0x0002: "actual_position",
                0x0008: "motor_current", 0x001F: "error_code", 0x0204: "torque_control_mode_max_speed",
                0x0114: "reset_output_encoder"}
    for index, name in expected.items():
        assert EROB_CAN.at(index) == name
        assert name in EROB_MODBUS
    assert EROB_CAN.at(0x0005, 1) == "current_speed"


EXAMPLE_ADDRESSES = sorted({(int(r["decoded"]["index"], 16), int(r["decoded"]["subindex"], 16)
                             if "subindex" in r["decoded"] else None, r["decoded"].get("unit", ""), r["id"])
                            for r in vectors("erob-can", "erob") if "index" in r["decoded"]},
                           key=lambda t: t[3])


@pytest.mark.parametrize(("index", "subindex", "unit", "vid"), EXAMPLE_ADDRESSES,
                         ids=[t[3] for t in EXAMPLE_ADDRESSES])
def test_every_example_address_is_mapped_with_its_unit(index: int, subindex: int | None, unit: str, vid: str) -> None:
    name = EROB_CAN.at(index, subindex)
    if unit and name != "analog_quantity_value":  # reads carry no unit; 0x01FE is speed or current by mode
        assert EROB_CAN.unit(name) == unit, (vid, name)


# ----------------------------------------------------------------------------- value conversion


def test_scaled_times() -> None:
    assert EROB_CAN.to_wire("dwell_time", 2000) == 100  # 100 ms = 2000 x 0.05 ms
    assert EROB_CAN.from_wire("dwell_time", 100) == 2000
    assert EROB_CAN.from_wire("struck_time", 5) == 100
    with pytest.raises(CommandError, match="whole number of ms"):
        EROB_CAN.to_wire("time_setting_of_achieving_position", 30)


def test_signed_and_unsigned_values() -> None:
    assert EROB_CAN.to_wire("target_relative_position", -10000) == -10000
    assert EROB_CAN.from_wire("target_relative_position", -10000) == -10000
    assert EROB_CAN.to_wire("module_serial", 0xFFFFFFFF) == -1
    assert EROB_CAN.from_wire("module_serial", -1) == 0xFFFFFFFF
    assert EROB_CAN.from_wire("module_configuration", -0x7F000000) == 0x81000000


def test_range_checks_use_the_parameter() -> None:
    with pytest.raises(CommandError):
        EROB_CAN.to_wire("operation_mode", 4)  # listed over CAN but not documented: refused
    with pytest.raises(CommandError):
        EROB_CAN.to_wire("can_address", 128)
    with pytest.raises(CommandError):
        EROB_CAN.to_wire("enable_the_motor", 2)
    assert EROB_CAN.to_wire("enable_the_motor", 1) == 1


def test_can_access_and_unit() -> None:
    assert EROB_CAN.access("continuous_current") is Access.R
    assert EROB_PARAMS["continuous_current"].access is Access.RW  # over Modbus
    assert EROB_CAN.access("profile_speed") is Access.RW
    assert EROB_CAN.unit("dwell_time") == "ms" and EROB_PARAMS["dwell_time"].unit == "0.05 ms"


# ----------------------------------------------------------------------------- error replies


def _appendix_rows() -> dict[int, tuple[int, str]]:
    lo = max(i for i, line in enumerate(MANUAL) if line.startswith("9. 附录"))
    rows = {}
    for line in MANUAL[lo:]:
        m = re.match(r"(\d+)\t0x([0-9A-F]{4})\t([^\t]*)", line)
        if m:
            rows[int(m.group(2), 16)] = (int(m.group(1)), _norm(m.group(3)))
    return rows


def test_error_reply_codes_are_appendix_1_with_its_text() -> None:
    rows = _appendix_rows()
    assert set(rows) == set(ecan.ERROR_REPLY_TEXT) == {0x15, 0x16, 0x1F, 0x27, 0x30, 0x32, 0x33, 0x56, 0x14A}
    for code, (number, printed) in rows.items():
        text = _norm(ecan.ERROR_REPLY_TEXT[code])
        assert printed and text.startswith(printed), (code, printed, text)
        info = ecan.describe_error_reply(code)
        assert info is FAULTS[code]
        assert info.source == f"eRunner v1.7 appendix 1 #{number}"
        assert info.text and info.hint


def test_unknown_error_reply_code_points_to_the_vendor_table() -> None:
    info = ecan.describe_error_reply(0x7777)
    assert info.code == 0x7777 and "not documented" in info.text


# -------------------------------------------------------------------------- module information


def test_module_information_example_of_7_5_3() -> None:
    # 7.5.3: diameter 1, reducer 2, ratio 3, mounting 1, brake 2, encoder 2, comm 1, torque 1, serial 1111
    info = ModuleInfo(serial=1111, model_info=(1 << 16) | (3 << 12),
                      configuration=2 | (1 << 4) | (1 << 8) | (2 << 16) | (2 << 20) | (1 << 24),
                      hardware_change=1, io_function=1,
                      version=2 | (1 << 4) | (0xB << 8) | (3 << 12) | (0xD << 16) | (5 << 20),
                      hardware_version=1005)
    assert info.model == "eRob70H100I-BM-18EN"
    assert info.serial_number == "07000001111"
    assert info.hardware_version_text == "1005_1_1"
    assert info.version_text == "MC2A.BC.DE"
    assert info.config == ModuleConfig()
    text = _norm(" ".join(MANUAL))
    for s in ("eRob70H100I-BM-18EN", "07000001111", "MC2A.BC.DE"):
        assert s in text


@pytest.mark.parametrize("model", ["eRob70H100I-BM-18EN", "eRob80H120I-BHM-18ET", "eRob142F50BT-FS-18CT",
                                   "eRob110H160T-BHS-18CN", "eRob90F80BI-FM-18ET", "eRob170H100I-BM-18EN"])
def test_module_information_round_trip(model: str) -> None:
    config = ModuleConfig.from_model(model)
    assert config.model == model
    info = ModuleInfo.build(config, 12345678, version="MC1E.Ee.ED", hardware_version=1005, firmware_version=150617150,
                            hardware_change=2, io_function=1)
    # a twin answers each value, a driver reads them back through the map
    read: dict[str, Any] = {}
    for name, value in info.values().items():
        key = EROB_CAN.key(name)
        assert key.index in (0x0001, 0x0232) and EROB_CAN.access(name) is Access.R
        raw = EROB_CAN.to_wire(name, value)
        assert -(1 << 31) <= raw < (1 << 31)
        read[name] = EROB_CAN.from_wire(name, raw)
    back = ModuleInfo.from_values(read)
    assert back == info
    assert back.model == model and back.config == config
    assert back.serial_number == f"{config.outer_diameter:03d}12345678"
    assert back.version_text == "MC1E.Ee.ED"
    assert back.hardware_version_text == "1005_2_1"
    assert ModuleInfo.build(model, 1) .model == model


def test_diameter_codes_7_and_8_are_70() -> None:
    for code in (1, 7, 8):
        info = ModuleInfo(5, code << 16 | 1 << 12, 1 | 1 << 4 | 1 << 8 | 1 << 16 | 1 << 20 | 1 << 24)
        assert info.model == "eRob70F50I-FS-18EN"
        assert info.serial_number == "07000000005"


def test_unknown_codes_show_as_question_marks() -> None:
    info = ModuleInfo(1, 0, 0)
    assert info.model == "eRob????-??-18??"
    assert info.serial_number == "???00000001"
    assert info.version_text == "MC??.??.??"
    with pytest.raises(CommandError):
        _ = info.config


@pytest.mark.parametrize("bad", ["eRob75H100I-BM-18EN", "eRob70X100I-BM-18EN", "eRob70H100I-BM-19EN", "erob70",
                                 "eRob70H90I-BM-18EN", "eRob70H100I-BQ-18EN"])
def test_bad_model_strings_are_refused(bad: str) -> None:
    with pytest.raises(CommandError):
        ModuleConfig.from_model(bad)


def test_bad_version_strings_are_refused() -> None:
    for bad in ("MC3A.BC.DE", "MC2A.BF.DE", "2A.BC.DE", "MC2A.BC.D"):
        with pytest.raises(CommandError):
            ecan.version_word(bad)
    assert ecan.version_word("MC2A.BC.DE") == 0x5D3B12


def test_module_information_firmware_requirement() -> None:
    assert ecan.MODULE_INFO_MIN_FIRMWARE == "X5061715X"
    assert ecan.module_info_supported(150617150) is True
    assert ecan.module_info_supported(950617159) is True
    assert ecan.module_info_supported(160000000) is True
    assert ecan.module_info_supported(520212171) is False  # the firmware of figure 3-6
    assert ecan.module_info_supported(150617140) is False
    assert ecan.module_info_supported(5061715) is None
    assert "520212171" in " ".join(MANUAL)
