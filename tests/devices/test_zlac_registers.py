"""ZLAC8015D Modbus register table: invariants, completeness against the manual, vectors, codecs."""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from typing import Any

import pytest

from joints.codecs import modbus as mb
from joints.devices.registers import Access, Register, snake_name
from joints.devices.zlac.registers import (
    CAN_BAUD_RATES,
    COUNTS_PER_REV,
    DEFAULTS_NOT_PRINTED,
    ENCODER_LINES,
    MANUAL_NAMES,
    RS485_BAUD_RATES,
    STATUS_BLOCK_START,
    STATUS_BLOCK_WORDS,
    UNNAMED,
    ZLAC8015D,
    ControlMode,
    ControlWord,
    Fault,
    QuickStopBehaviour,
    SyncMode,
    describe,
    split_left_right,
)
from joints.errors import CommandError, RegisterError
from testdata import MANUALS, VECTORS

MANUAL = MANUALS / "zlac8015d-rs485-modbus-manual-v1.04.txt"

SIZES = {"uint16": 1, "int16": 1, "uint32": 2, "int32": 2}
UNITS = {"", "ms", "10 ms", "r/min", "0.1 r/min", "mA", "mA/s", "0.1 A", "0.01 V", "counts",
         "10 counts", "%", "deg", "degC", "0.1 degC", "lines"}
T = ZLAC8015D


def _pairs() -> list[Register]:
    return [r for r in T if r.words == 2]


def _all_words() -> set[int]:
    return {a for r in T for a in range(r.address, r.address + r.words)}


# ---------------------------------------------------------------------------- invariants


def test_size() -> None:
    assert len(T) == 108
    assert T.device == "zlac8015d"
    assert len(_pairs()) == 4


def test_unique_names_and_addresses() -> None:
    names = [r.name for r in T]
    addresses = [r.address for r in T]
    assert len(set(names)) == len(names)
    assert len(set(addresses)) == len(addresses)
    assert addresses == sorted(addresses)


def test_no_overlapping_words() -> None:
    used: dict[int, str] = {}
    for reg in T:
        for a in range(reg.address, reg.address + reg.words):
            assert a not in used, f"0x{a:04X} used by {used[a]} and {reg.name}"
            used[a] = reg.name
            assert T.owner(a) is reg


def test_sizes_match_types() -> None:
    for reg in T:
        assert reg.type in ("uint16", "int16", "int32"), reg.name
        assert reg.words == SIZES[reg.type], reg.name
        assert reg.low_word_first is False, reg.name
    assert {r.name for r in _pairs()} == {
        "target_position_left", "target_position_right",
        "actual_motor_position_left", "actual_motor_position_right",
    }


def test_names_are_snake_case_identifiers() -> None:
    for reg in T:
        assert reg.name.isidentifier(), reg.name
        assert re.fullmatch(r"[a-z0-9]+(_[a-z0-9]+)*", reg.name), reg.name
        assert snake_name(reg.name) == reg.name


def test_names_come_from_printed_names() -> None:
    assert set(MANUAL_NAMES) | set(UNNAMED) == set(T.names())
    assert not set(MANUAL_NAMES) & set(UNNAMED)
    for name, printed in MANUAL_NAMES.items():
        assert snake_name(re.sub(r"\s*(high|low) 16 bits", "", printed)) == name, printed
    assert UNNAMED == {"unnamed_200c": 829, "unnamed_2015": 969}


def test_left_right_banks_mirror() -> None:
    for left in T:
        if 0x2030 <= left.address <= 0x204A:
            right = T[left.address + 0x30]
            assert left.name.endswith("_left") and right.name == left.name[:-5] + "_right"
            for field in ("type", "access", "unit", "minimum", "maximum", "default", "persistent"):
                assert getattr(left, field) == getattr(right, field), (left.name, field)
    for name in T.names():
        if name.endswith("_left"):
            assert name[:-5] + "_right" in T, name


def test_units_access_descriptions() -> None:
    for reg in T:
        assert reg.unit in UNITS, (reg.name, reg.unit)
        assert reg.access in (Access.R, Access.RW), reg.name
        assert reg.description, reg.name
    assert all(r.access is Access.R for r in T if r.address >= 0x20A0)
    assert T["control_word"].access is Access.RW


def test_bounds_inside_type_range_and_defaults_inside_bounds() -> None:
    for reg in T:
        lo, hi = reg.type_range
        if reg.minimum is not None:
            assert lo <= reg.minimum, reg.name
        if reg.maximum is not None:
            assert reg.maximum <= hi, reg.name
        if reg.minimum is not None and reg.maximum is not None:
            assert reg.minimum <= reg.maximum, reg.name
        # the control word's 0 is its power-on read-back, not a command
        if reg.name not in DEFAULTS_NOT_PRINTED and reg.name != "control_word":
            reg.check(reg.default)


def test_documented_values() -> None:
    expect = {
        "target_velocity_left": ("int16", "r/min", -3000, 3000, 0),
        "target_torque_right": ("int16", "mA", -30000, 30000, 0),
        "acceleration_time_left": ("uint16", "ms", 0, 32767, 500),
        "deceleration_time_right": ("uint16", "ms", 0, 32767, 500),
        "deceleration_time_of_quick_stop_left": ("uint16", "ms", 0, 32767, 10),
        "target_speed_left": ("uint16", "r/min", 1, 1000, 120),
        "actual_velocity_right": ("int16", "0.1 r/min", None, None, 0),
        "actual_torque_left": ("int16", "0.1 A", -300, 300, 0),
        "torque_rate_left": ("uint16", "mA/s", None, None, 300),
        "dc_voltage": ("uint16", "0.01 V", None, None, 0),
        "communication_offline_time": ("uint16", "ms", 0, 32767, 1000),
        "rs485_node_id": ("uint16", "", 1, 127, 1),
        "rs485_baud_rate": ("uint16", "", 0, 6, 2),
        "encoder_line_left": ("uint16", "lines", 0, 4096, ENCODER_LINES),
        "hall_offset_angle_right": ("int16", "deg", -360, 360, 0),
        "over_temperature_threshold_left": ("uint16", "0.1 degC", 0, 1200, 800),
        "target_position_left": ("int32", "counts", -0x7FFFFFFF, 0x7FFFFFFF, 0),
        "actual_motor_position_right": ("int32", "counts", -0x7FFFFFFF, 0x7FFFFFFF, 0),
        "control_mode": ("uint16", "", 0, 4, 0),
        "synchronous_asynchronous_control_status": ("uint16", "", 0, 1, 0),
        "quick_stop_control": ("uint16", "", 5, 7, 0),
        "x0_function_choice": ("uint16", "", 0, 9, 9),
        "velocity_observer_coefficient_3_left": ("uint16", "", 0, 30000, 350),
    }
    for name, (type_, unit, lo, hi, default) in expect.items():
        reg = T[name]
        assert (reg.type, reg.unit, reg.minimum, reg.maximum, reg.default) == (
            type_, unit, lo, hi, default), name
    assert T["target_velocity_left"].address == 0x2088
    assert T["acceleration_time_left"].address == 0x2080
    assert "DOC-ZLAC-1" in T["synchronous_asynchronous_control_status"].description
    assert "EXAMPLES" in T["synchronous_asynchronous_control_status"].description
    assert "DOC-ZLAC-3" in T["rs485_node_id"].description
    assert "DOC-ZLAC-4" in T["in_absolute_position_control_reset_the_zero_point"].description
    assert "DOC-ZLAC-5" in T["torque_rate_right"].description
    assert "DOC-ZLAC-6" in T["output_effective_level"].description


def test_persistent_flags() -> None:
    persistent = {r.name for r in T if r.persistent}
    common = {"rs485_node_id", "rs485_baud_rate", "driver_state", "maximum_motor_speed",
              "register_parameter_settings", "can_node_id", "can_baud_rate",
              "whether_store_rw_register_to_eeprom"}
    bank = {"encoder_line", "hall_offset_angle", "overload_factor", "rated_current",
            "maximum_current", "overload_protection_time", "position_following_error_threshold",
            "poles_of_motor", "over_temperature_threshold"}
    assert persistent == common | {f"{b}_{s}" for b in bank for s in ("left", "right")}
    assert not any(r.persistent for r in T if r.access is Access.R)
    # "Not saved." (lines 802, 808) - position counters only
    assert not T["clear_feedback_position"].persistent
    assert not T["in_absolute_position_control_reset_the_zero_point"].persistent


def test_lo_word_address_is_rejected() -> None:
    for lo, owner in ((0x208B, "target_position_left"), (0x20A8, "actual_motor_position_left"),
                      (0x208D, "target_position_right"), (0x20AA, "actual_motor_position_right")):
        with pytest.raises(RegisterError, match=f"second word of {owner}"):
            T[lo]
    with pytest.raises(RegisterError):
        T[0x2041]  # not in chapter 4


# ------------------------------------------------------------------------ codec round trips


@pytest.mark.parametrize(
    ("name", "value", "words"),
    [
        ("target_velocity_left", -100, (0xFF9C,)),  # 3.1: 01 06 20 88 FF 9C
        ("target_velocity_right", 100, (0x0064,)),
        ("target_velocity_left", -3000, (0xF448,)),
        ("target_torque_left", -2000, (0xF830,)),  # 3.4: 01 06 20 90 F8 30
        ("target_torque_right", 2000, (0x07D0,)),
        ("hall_offset_angle_left", -360, (0xFE98,)),
        ("target_position_left", 20480, (0x0000, 0x5000)),  # 3.2: 00 00 50 00
        ("target_position_right", -20480, (0xFFFF, 0xB000)),  # 3.2: FF FF B0 00
        ("target_position_left", 0x7FFFFFFF, (0x7FFF, 0xFFFF)),
        ("target_position_left", -0x7FFFFFFF, (0x8000, 0x0001)),
        ("actual_motor_position_left", -3 * COUNTS_PER_REV, (0xFFFF, 0xD000)),
        ("actual_motor_position_right", 0x12345678, (0x1234, 0x5678)),
    ],
)
def test_round_trip(name: str, value: int, words: tuple[int, ...]) -> None:
    reg = T[name]
    assert reg.to_words(value) == words
    assert reg.from_words(words) == value


def test_out_of_range_rejected() -> None:
    for name, value in (("target_velocity_left", 3001), ("target_velocity_right", -3001),
                        ("target_torque_left", 30001), ("acceleration_time_left", 32768),
                        ("target_speed_left", 0), ("control_mode", 5), ("rs485_node_id", 0),
                        ("target_position_left", -0x80000000), ("hall_offset_angle_left", 361)):
        with pytest.raises(CommandError):
            T[name].to_words(value)


def test_sync_velocity_block_encodes_like_the_manual() -> None:
    # 3.1 synchronous velocity control: 01 10 20 88 00 02 04 FF 9C FF 9C
    assert T.encode_block({"target_velocity_left": -100, "target_velocity_right": -100}) == (
        0x2088, [0xFF9C, 0xFF9C])
    # 3.2 synchronous relative position: 01 10 20 8A 00 04 08 FF FF B0 00 FF FF B0 00
    assert T.encode_block({"target_position_left": -20480, "target_position_right": -20480}) == (
        0x208A, [0xFFFF, 0xB000, 0xFFFF, 0xB000])


# ----------------------------------------------------------------------------- status block


def test_status_block_is_contiguous_and_covers_both_wheels() -> None:
    assert (STATUS_BLOCK_START, STATUS_BLOCK_WORDS) == (0x20A5, 10)
    assert T.span("error_code_left", "actual_torque_right") == (STATUS_BLOCK_START, STATUS_BLOCK_WORDS)
    assert STATUS_BLOCK_WORDS <= mb.MAX_READ
    for a in range(STATUS_BLOCK_START, STATUS_BLOCK_START + STATUS_BLOCK_WORDS):
        owner = T.owner(a)
        assert owner is not None, f"gap at 0x{a:04X}"
        assert owner.address >= STATUS_BLOCK_START
        assert owner.address + owner.words <= STATUS_BLOCK_START + STATUS_BLOCK_WORDS
    words = [0] * STATUS_BLOCK_WORDS

    def put(name: str, value: int) -> None:
        reg = T[name]
        i = reg.address - STATUS_BLOCK_START
        words[i : i + reg.words] = reg.to_words(value)

    put("error_code_left", Fault.HALL_ERROR | Fault.OVER_CURRENT)
    put("actual_motor_position_left", -20480)
    put("actual_motor_position_right", 20480)
    put("actual_velocity_left", -1000)
    put("actual_velocity_right", 1000)
    put("actual_torque_left", -25)
    put("actual_torque_right", 300)
    out = T.decode_block(STATUS_BLOCK_START, words)
    assert out == {
        "error_code_left": 0x0204, "error_code_right": 0,
        "actual_motor_position_left": -20480, "actual_motor_position_right": 20480,
        "actual_velocity_left": -1000, "actual_velocity_right": 1000,
        "actual_torque_left": -25, "actual_torque_right": 300,
    }
    assert describe(out["error_code_left"]) == ["Over current", "Hall error"]
    # the FC03 request for it
    frame = mb.encode(mb.ReadHoldingRegisters(1, STATUS_BLOCK_START, STATUS_BLOCK_WORDS))
    assert frame[:6] == bytes.fromhex("01 03 20 A5 00 0A")


def test_packed_two_wheel_words() -> None:
    assert split_left_right(0x0100) == (1, 0)
    assert split_left_right(0x2A19) == (42, 25)
    for name in ("motor_state", "hall_state", "motor_temperature"):
        assert "high byte = left" in T[name].description


# ------------------------------------------------------------------------------ enums, faults


def test_enums() -> None:
    assert {m.name: int(m) for m in ControlWord} == {
        "QUICK_STOP": 0x05, "CLEAR_FAULT": 0x06, "STOP": 0x07, "ENABLE": 0x08,
        "START_SYNC": 0x10, "START_LEFT": 0x11, "START_RIGHT": 0x12}
    assert [int(m) for m in ControlMode] == [0, 1, 2, 3, 4]
    assert (ControlMode.RELATIVE_POSITION, ControlMode.ABSOLUTE_POSITION,
            ControlMode.VELOCITY, ControlMode.TORQUE) == (1, 2, 3, 4)
    assert (SyncMode.ASYNCHRONOUS, SyncMode.SYNCHRONOUS) == (0, 1)  # EXAMPLES, DOC-ZLAC-1
    assert [int(m) for m in QuickStopBehaviour] == [5, 6, 7]
    assert (T["quick_stop_control"].minimum, T["quick_stop_control"].maximum) == (
        min(QuickStopBehaviour), max(QuickStopBehaviour))
    assert (T["control_mode"].minimum, T["control_mode"].maximum) == (
        min(ControlMode), max(ControlMode))
    assert (T["control_word"].minimum, T["control_word"].maximum) == (
        min(ControlWord), max(ControlWord))
    assert RS485_BAUD_RATES[T["rs485_baud_rate"].default] == 115200  # section 1
    assert sorted(RS485_BAUD_RATES.values()) == [9600, 19200, 38400, 57600, 115200, 128000, 256000]
    assert CAN_BAUD_RATES[T["can_baud_rate"].default] == 500_000
    assert ENCODER_LINES == 1024 and COUNTS_PER_REV == 4096
    assert T["encoder_line_left"].default == T["encoder_line_right"].default == ENCODER_LINES


def test_fault_bits() -> None:
    assert [int(f) for f in Fault] == [1 << i for i in range(11)]
    assert describe(0) == []
    assert describe(Fault.OVER_VOLTAGE) == ["Over voltage"]
    assert describe(0x0400) == ["Motor temperature over temperature"]
    assert describe(Fault.UNDER_VOLTAGE | Fault.EEPROM_ERROR | Fault.POSITION_FOLLOWING_ERROR) == [
        "Under voltage", "Position following error", "EEPROM error"]
    assert describe(0x07FF) == [
        "Over voltage", "Under voltage", "Over current", "Over load", "Current following error",
        "Position following error", "Velocity following error", "Reference voltage error",
        "EEPROM error", "Hall error", "Motor temperature over temperature"]
    assert describe(0x8001) == ["Over voltage", "undocumented fault bit 0x8000"]
    flags = Fault(T["error_code_right"].from_words((0x0006,)))
    assert Fault.UNDER_VOLTAGE in flags and Fault.OVER_CURRENT in flags
    assert Fault.OVER_VOLTAGE not in flags


# ------------------------------------------------------------------------- manual (OCR text)

_MARK = re.compile(r"<\|[^|]*\|>")
_INDEX = re.compile(r"^(?:20|>0|50)[0-9A-F]{2}l?h?$")
#: OCR-damaged index tokens of chapter 4 -> address (line-specific where the token is valid)
_INDEX_REPAIRS = {">046h": 0x2046, ">047h": 0x2047, "5048h": 0x2048, "5018h": 0x2018,
                  "2079": 0x2079, "20A1lh": 0x20A1}
_LINE_REPAIRS = {1026: 0x2049}  # a second "2045h" between 0x2048 and 0x204A
_UNSIGNED = re.compile(r"^[Uu][Uuil1e\u00e96]{1,5}$")  # U16 as OCR'd: Uul6, ulé, uil6e, U6, Ul ...
_SIGNED = re.compile(r"^[1I]16$")
_ACCESS = {"RW": Access.RW, "RwW": Access.RW, "RO": Access.R}
_DEFAULT = re.compile(r"\b(?:RW|RwW|RO)\s+(\d+)\s*(?:ms|r/min)?\s*$")
_RANGE = re.compile(r"Range:\s*(-?\d+)\s*[-~]\s*\+?(-?\d+)")
_NAME_OCR = [(re.compile(r"Sofeware"), "Software"), (re.compile(r"\bVI ?(K[pif])"), r"Vl \1"),
             (re.compile(r"\bYO\b"), "Y0")]


@dataclass
class Row:
    address: int
    line: int  #: 1-based line of the index
    block: list[str]  #: index line .. line before the next index


def _lines() -> list[str]:
    if not MANUAL.is_file():
        pytest.skip(f"ZLAC manual not found at {MANUAL} (../shared absent)")
    return [_MARK.sub("", ln) for ln in MANUAL.read_text(encoding="utf-8").splitlines()]


def _rows(lines: list[str], first: int, last: int) -> list[Row]:
    """Index rows between 1-based lines first..last (OCR-repaired index tokens)."""
    rows: list[Row] = []
    for n in range(first, last + 1):
        tokens = lines[n - 1].split()
        if not tokens or not _INDEX.match(tokens[0]):
            continue
        tok = tokens[0]
        address = _LINE_REPAIRS.get(n) or _INDEX_REPAIRS.get(tok) or int(tok.rstrip("h"), 16)
        rows.append(Row(address, n, []))
    for i, row in enumerate(rows):
        end = rows[i + 1].line if i + 1 < len(rows) else last + 1
        row.block = lines[row.line - 1 : end - 1]
    return rows


@pytest.fixture(scope="module")
def manual() -> list[str]:
    return _lines()


@pytest.fixture(scope="module")
def chapter4(manual: list[str]) -> tuple[int, int]:
    start = next(i for i, ln in enumerate(manual, 1) if ln.startswith("4. ADDRESS DIRECTIONARY"))
    end = next(i for i, ln in enumerate(manual, 1) if i > start and ln.startswith("Note:"))
    assert (start, end) == (778, 1371)
    return start, end


@pytest.fixture(scope="module")
def rows4(manual: list[str], chapter4: tuple[int, int]) -> list[Row]:
    return _rows(manual, *chapter4)


def _reg_of(address: int) -> Register:
    reg = T.owner(address)
    assert reg is not None, f"0x{address:04X} not in the table"
    return reg


def test_every_printed_20xxh_index_is_in_the_table(manual: list[str], chapter4: tuple[int, int]) -> None:
    start, end = chapter4
    text = "\n".join(manual[start - 1 : end])
    printed = {int(m, 16) for m in re.findall(r"\b(20[0-9A-F]{2})h\b", text)}
    assert len(printed) >= 100
    words = _all_words()
    missing = sorted(a for a in printed if a not in words)
    assert not missing, [hex(a) for a in missing]
    for a in printed:  # a register start, or the low word of a 32-bit pair
        reg = _reg_of(a)
        assert a == reg.address or (reg.words == 2 and a == reg.address + 1)


def test_chapter4_indexes_match_the_table_exactly(rows4: list[Row]) -> None:
    addresses = [r.address for r in rows4]
    assert addresses == sorted(set(addresses)), "repaired index sequence must be strictly increasing"
    assert set(addresses) == _all_words()  # both words of each pair are printed
    assert len(rows4) == len(T) + len(_pairs())


def test_chapter4_types_access_defaults_ranges(rows4: list[Row]) -> None:
    checked = {"type": 0, "access": 0, "default": 0, "range": 0}
    default_exceptions = {0x2001: (4, 1)}  # DOC-ZLAC-3: printed 4, section 1 says 1
    range_exceptions = {0x20A3, 0x20A4}  # per-byte ranges of packed two-wheel words
    for row in rows4:
        reg = _reg_of(row.address)
        where = f"line {row.line}: 0x{row.address:04X} {reg.name}"
        tokens = [t.strip("|).;") for ln in row.block for t in ln.split()]
        types = [t for t in tokens if _UNSIGNED.match(t) or _SIGNED.match(t)]
        if types:
            assert reg.signed == bool(_SIGNED.match(types[0])), where
            checked["type"] += 1
        access = [_ACCESS[t] for t in tokens if t in _ACCESS]
        if access:
            assert reg.access is access[0], where
            checked["access"] += 1
        if row.address != reg.address:
            continue  # low word of a pair: type/access only
        m = _DEFAULT.search(row.block[0])
        if m:
            printed = int(m.group(1))
            if row.address in default_exceptions:
                assert (printed, reg.default) == default_exceptions[row.address], where
            else:
                assert reg.default == printed, where
            checked["default"] += 1
        ranges = [_RANGE.search(ln) for ln in row.block]
        found = [(int(m.group(1)), int(m.group(2))) for m in ranges if m]
        if found and row.address not in range_exceptions:
            assert (reg.minimum, reg.maximum) == found[0], where
            checked["range"] += 1
    assert checked["type"] >= 95 and checked["access"] >= 100, checked
    assert checked["default"] >= 60 and checked["range"] >= 50, checked


def test_chapter4_names_are_printed_near_their_index(manual: list[str], rows4: list[Row]) -> None:
    text = "\n".join(manual)
    for pattern, repl in _NAME_OCR:
        text = pattern.sub(repl, text)
    lines = text.splitlines()
    starts = {row.address: row for row in rows4}
    for name, printed in MANUAL_NAMES.items():
        reg = T[name]
        row = starts[reg.address]
        end = row.line + len(row.block)
        window = re.sub(r"[^0-9a-z]", "", " ".join(lines[row.line - 3 : end - 1]).lower())
        words = re.findall(r"[0-9a-z]+", printed.lower())
        if 0x2030 <= reg.address <= 0x207A:  # banks print no side; it is the section heading
            words = words[:-1]
        for word in words:
            assert word in window, f"line {row.line}: {word!r} of {printed!r} not printed there"
    for name, line in UNNAMED.items():
        assert re.sub(r"[^0-9a-z]", "", lines[line - 1].lower()) == name.split("_")[1] + "h"


def test_bank_headings(manual: list[str], rows4: list[Row]) -> None:
    left = next(i for i, ln in enumerate(manual, 1) if ln.strip() == "Left motor parameter")
    right = next(i for i, ln in enumerate(manual, 1) if ln.strip() == "Right motor parameter")
    control = next(i for i, ln in enumerate(manual, 1) if ln.strip() == "Control parameter")
    for row in rows4:
        name = _reg_of(row.address).name
        if left < row.line < right:
            assert name.endswith("_left") and 0x2030 <= row.address <= 0x204A, name
        elif right < row.line < control:
            assert name.endswith("_right") and 0x2060 <= row.address <= 0x207A, name


def test_chapter3_tables_agree(manual: list[str]) -> None:
    rows3 = _rows(manual, 308, 777)
    assert {r.address for r in rows3} >= {0x200D, 0x200E, 0x200F, 0x2080, 0x2088, 0x208A,
                                         0x208E, 0x2090, 0x20A7, 0x20AB, 0x20AD, 0x2016}
    for row in rows3:
        reg = _reg_of(row.address)
        where = f"line {row.line}: 0x{row.address:04X} {reg.name}"
        tokens = [t.strip("|).;") for t in row.block[0].split()]
        types = [t for t in tokens if _UNSIGNED.match(t) or _SIGNED.match(t)]
        if types:
            assert reg.signed == bool(_SIGNED.match(types[0])), where
        m = _DEFAULT.search(row.block[0])
        if m and row.address == reg.address:
            assert reg.default == int(m.group(1)), where


def test_fault_list_of_section_3_6(manual: list[str]) -> None:
    found = 0
    for ln in manual[759:773]:
        m = re.match(r"^0x([0-9A-F]{4})\s+(.+)$", ln.strip())
        if not m:
            continue
        code, text = int(m.group(1), 16), m.group(2).strip()
        assert describe(code) == ([] if code == 0 else [text]), ln
        found += 1
    assert found == 12


# --------------------------------------------------------------------------- vectors.json


def _zlac_vectors() -> list[dict[str, Any]]:
    if not VECTORS.is_file():
        return []
    records = json.loads(VECTORS.read_text(encoding="utf-8"))
    return [r for r in records if r.get("record_type") == "vector"
            and r.get("device") == "zlac8015d" and r.get("protocol") == "modbus-rtu"]


ZLAC_VECTORS = _zlac_vectors()
BY_ID = {r["id"]: r for r in ZLAC_VECTORS}
#: names the vectors use that are not the manual's Name column
VECTOR_NAME_ALIASES = {"target_speed_in_position_mode_left": "target_speed_left",
                       "target_speed_in_position_mode_right": "target_speed_right"}


def _vector_name(printed: str) -> str:
    name = snake_name(printed)
    return VECTOR_NAME_ALIASES.get(name, name)


def _frame(record: dict[str, Any]) -> bytes:
    return bytes.fromhex(record.get("correct_hex") or record["hex"])


def _decode_request(record: dict[str, Any]) -> mb.Message:
    codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
    codec.feed(_frame(record))
    msg = codec.next_message()
    assert msg is not None and codec.next_message() is None
    return msg


def _decode_reply(record: dict[str, Any]) -> mb.Message:
    request = _decode_request(BY_ID[record["pair"]])
    assert not isinstance(request, mb.UnsupportedRequest)
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    codec.expect_reply_to(request)  # type: ignore[arg-type]
    codec.feed(_frame(record))
    msg = codec.next_message()
    assert msg is not None and codec.next_message() is None
    return msg


def _request_address(record: dict[str, Any]) -> int:
    """Start address of the request a read reply answers."""
    request = _decode_request(BY_ID[record["pair"]])
    assert isinstance(request, mb.ReadHoldingRegisters)
    return request.address


def _tiles(address: int, count: int) -> list[Register]:
    """The registers that exactly tile [address, address + count)."""
    regs: list[Register] = []
    a = address
    while a < address + count:
        reg = T[a]  # raises for gaps and for the low word of a pair
        regs.append(reg)
        a += reg.words
    assert a == address + count, f"block 0x{address:04X}+{count} splits a 32-bit pair"
    return regs


@pytest.mark.skipif(not ZLAC_VECTORS, reason=f"vector file not found: {VECTORS}")
def test_vectors_present() -> None:
    assert len(ZLAC_VECTORS) == 132


@pytest.mark.parametrize("record", [pytest.param(r, id=r["id"]) for r in ZLAC_VECTORS]
                         or [pytest.param(None, marks=pytest.mark.skip(reason="no vectors"))])
def test_vector_decodes_to_table_registers(record: dict[str, Any]) -> None:
    msg = _decode_request(record) if record["direction"] == "request" else _decode_reply(record)
    decoded = record.get("decoded_corrected") or record["decoded"]
    values: dict[int, int] = {}
    if isinstance(msg, mb.WriteSingleRegister | mb.WriteSingleRegisterReply):
        reg = T[msg.address]
        assert reg.words == 1 and reg.access.writable
        values[reg.address] = reg.check(reg.from_words((msg.value,)))
        assert _vector_name(decoded["name"]) == reg.name
        assert decoded["type"] == reg.type
        assert decoded["value"] == values[reg.address]
    elif isinstance(msg, mb.WriteMultipleRegisters | mb.ReadRegistersReply):
        start = msg.address if isinstance(msg, mb.WriteMultipleRegisters) else _request_address(record)
        for reg in _tiles(start, len(msg.values)):
            i = reg.address - start
            values[reg.address] = reg.check(reg.from_words(msg.values[i : i + reg.words]))
            if isinstance(msg, mb.WriteMultipleRegisters):
                assert reg.access.writable, reg.name
    elif isinstance(msg, mb.ReadHoldingRegisters):
        _tiles(msg.address, msg.count)
    elif isinstance(msg, mb.WriteMultipleRegistersReply):
        assert all(r.access.writable for r in _tiles(msg.address, msg.count))
    else:  # pragma: no cover - the ZLAC vectors hold no other messages
        pytest.fail(f"unexpected message {msg!r}")
    for v in decoded.get("values", []):
        reg = T[int(v["register"].split("/")[0], 16)]
        assert _vector_name(v["name"]) == reg.name
        assert v["type"] == reg.type
        assert values[reg.address] == v["value"]
    if record["id"].startswith("zlac-modbus-2.1-ex-send"):
        assert isinstance(msg, mb.ReadHoldingRegisters)
        assert [r.name for r in _tiles(msg.address, msg.count)] == [
            "actual_velocity_left", "actual_velocity_right"]


@pytest.mark.skipif(not ZLAC_VECTORS, reason=f"vector file not found: {VECTORS}")
def test_vectors_use_control_words_and_sync_modes_of_the_examples() -> None:
    seen: dict[str, set[int]] = {}
    for record in ZLAC_VECTORS:
        if record["direction"] != "request":
            continue
        msg = _decode_request(record)
        if isinstance(msg, mb.WriteSingleRegister):
            seen.setdefault(T[msg.address].name, set()).add(msg.value)
    assert seen["control_word"] == {int(c) for c in ControlWord}
    assert seen["control_mode"] == {ControlMode.RELATIVE_POSITION, ControlMode.VELOCITY,
                                    ControlMode.TORQUE}
    # DOC-ZLAC-1: the asynchronous example writes 0, the synchronous one writes 1
    async_init = _decode_request(BY_ID["zlac-modbus-3.2-asyncinit-step1-send"])
    sync_init = _decode_request(BY_ID["zlac-modbus-3.2-syncinit-step1-send"])
    assert isinstance(async_init, mb.WriteSingleRegister)
    assert isinstance(sync_init, mb.WriteSingleRegister)
    assert (async_init.address, async_init.value) == (0x200F, SyncMode.ASYNCHRONOUS)
    assert (sync_init.address, sync_init.value) == (0x200F, SyncMode.SYNCHRONOUS)
    # the async sequence starts wheels separately, the sync one together
    assert _decode_request(BY_ID["zlac-modbus-3.2-left-step2-send"]) == mb.WriteSingleRegister(
        1, 0x200E, ControlWord.START_LEFT)
    assert _decode_request(BY_ID["zlac-modbus-3.2-sync-step2-send"]) == mb.WriteSingleRegister(
        1, 0x200E, ControlWord.START_SYNC)
    # the printed 'stop'/'enable' frames to 0x2031 are corrected to the control word
    for vid in ("zlac-modbus-3.1-left-step3-send", "zlac-modbus-3.4-torqinit-step4-send"):
        msg = _decode_request(BY_ID[vid])
        assert isinstance(msg, mb.WriteSingleRegister) and T[msg.address].name == "control_word"


@pytest.mark.skipif(not ZLAC_VECTORS, reason=f"vector file not found: {VECTORS}")
def test_read_velocity_example_reply() -> None:
    # 2.1: reply 00 64 00 64 -> 100 x 0.1 r/min = 10 r/min on both wheels
    msg = _decode_reply(BY_ID["zlac-modbus-2.1-ex-recv"])
    assert isinstance(msg, mb.ReadRegistersReply)
    assert T.decode_block(_request_address(BY_ID["zlac-modbus-2.1-ex-recv"]), msg.values) == {
        "actual_velocity_left": 100, "actual_velocity_right": 100}
    assert T["actual_velocity_left"].unit == "0.1 r/min"
    # 2.3: encoder line (Left) 1024, hall offset angle (Left) 0
    req = _decode_request(BY_ID["zlac-modbus-2.3-ex-send"])
    assert isinstance(req, mb.WriteMultipleRegisters)
    assert T.decode_block(req.address, req.values) == {
        "encoder_line_left": ENCODER_LINES, "hall_offset_angle_left": 0}
