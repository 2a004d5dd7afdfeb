"""eRob Modbus RTU register table: invariants, completeness against the manual, codecs."""

from __future__ import annotations

import re
from dataclasses import dataclass

import pytest

from joints.devices.erob.registers import (
    COUNTS_PER_REV,
    EROB_MODBUS,
    MANUAL_DEFINITIONS,
    STATUS_BLOCK_START,
    STATUS_BLOCK_WORDS,
    AchieveStatus,
    BaudRate,
    MotionMode,
    MotionStatus,
    OperationMode,
)
from joints.devices.registers import Access, Register, snake_name
from joints.errors import CommandError, RegisterError
from testdata import MANUALS

MANUAL_EN = MANUALS / "erob-modbus-rtu-manual-v1.6-en.txt"

SIZES = {"uint16": 1, "int16": 1, "uint32": 2, "int32": 2}
UNITS = {"count", "count/s", "count/s^2", "mA", "mV", "ms", "0.05 ms", "degC", "mNm", "bps", ""}
ACCESS = {"R": Access.R, "R/W": Access.RW, "Command": Access.COMMAND}


# ---------------------------------------------------------------------------- invariants


def test_unique_names_and_addresses() -> None:
    names = [r.name for r in EROB_MODBUS]
    addresses = [r.address for r in EROB_MODBUS]
    assert len(set(names)) == len(names)
    assert len(set(addresses)) == len(addresses)


def test_no_overlapping_words() -> None:
    used: dict[int, str] = {}
    for reg in EROB_MODBUS:
        for a in range(reg.address, reg.address + reg.words):
            assert a not in used, f"0x{a:04X} used by {used[a]} and {reg.name}"
            used[a] = reg.name


def test_sizes_match_types() -> None:
    for reg in EROB_MODBUS:
        assert reg.type in SIZES, reg
        assert reg.words == SIZES[reg.type], reg
        # eRob: every 32-bit value is a signed int32, Hi word first.
        if reg.words == 2:
            assert reg.type == "int32", reg.name
        assert reg.low_word_first is False, reg.name


def test_names_are_snake_case_identifiers() -> None:
    for reg in EROB_MODBUS:
        assert reg.name.isidentifier(), reg.name
        assert re.fullmatch(r"[a-z0-9]+(_[a-z0-9]+)*", reg.name), reg.name
        assert snake_name(reg.name) == reg.name


def test_names_come_from_manual_definitions() -> None:
    assert set(MANUAL_DEFINITIONS) == set(EROB_MODBUS.names())
    for name, definition in MANUAL_DEFINITIONS.items():
        assert snake_name(definition) == name, definition


def test_units_and_access_are_from_the_allowed_sets() -> None:
    for reg in EROB_MODBUS:
        assert reg.unit in UNITS, (reg.name, reg.unit)
        assert isinstance(reg.access, Access)
        assert reg.description, reg.name


def test_bounds_are_inside_type_range() -> None:
    for reg in EROB_MODBUS:
        lo, hi = reg.type_range
        if reg.minimum is not None:
            assert lo <= reg.minimum, reg.name
        if reg.maximum is not None:
            assert reg.maximum <= hi, reg.name
        if reg.minimum is not None and reg.maximum is not None:
            assert reg.minimum <= reg.maximum, reg.name


def test_documented_types_bounds_and_flags() -> None:
    t = EROB_MODBUS
    assert t["part_of_power_temperature"].type == "int16"
    for name in ("error_code", "motion_status", "status_of_achieving_position",
                 "operation_mode", "motion_mode", "control_source"):
        assert t[name].type == "uint16", name
    for name in ("position_reaches_set_precision", "time_setting_of_achieving_position"):
        assert (t[name].type, t[name].access) == ("uint16", Access.RW)
    bounds = {
        "modbus_address": (1, 255),
        "modbus_baud_rate": (1, 4),
        "modbus_communication_timeout_duration": (0, 4000),
        "operation_mode": (1, 3),
        "motion_mode": (0, 2),
        "control_source": (0, 1),
        "enable_the_motor": (0, 1),
        "power_temperature_protection_value": (None, None),
    }
    for name, (lo, hi) in bounds.items():
        assert (t[name].minimum, t[name].maximum) == (lo, hi), name
    assert "85" in t["power_temperature_protection_value"].description
    persistent = {r.name for r in t if r.persistent}
    assert persistent == {"modbus_address", "modbus_baud_rate", "save_parameters",
                          "reset_output_encoder"}
    with pytest.raises(CommandError):
        t["modbus_address"].to_words(0)
    with pytest.raises(CommandError):
        t["modbus_communication_timeout_duration"].to_words(4001)
    assert t["modbus_communication_timeout_duration"].to_words(4000) == (4000,)


# ------------------------------------------------------------------- manual completeness


@dataclass
class ManualRow:
    address: int
    definition: str
    access: str
    words: int
    line: int


_ROW = re.compile(r"^0x([0-9A-Fa-f]{4})\t(\d+)\t([^\t]+)\t([^\t]+)\t")


def _chapter4_rows(text: str) -> list[ManualRow]:
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("## Chapter 4 Parameter Register"))
    end = next(i for i, ln in enumerate(lines) if i > start and ln.startswith("# Chapter 5"))
    rows: list[ManualRow] = []
    for i in range(start, end):
        m = _ROW.match(lines[i])
        if m is None:
            continue
        address, decimal = int(m.group(1), 16), int(m.group(2))
        assert address == decimal, f"line {i + 1}: hex/dec mismatch"
        definition, access = m.group(3).strip(), m.group(4).strip()
        if definition.endswith("(Lo)"):
            hi = rows[-1]
            assert hi.definition.endswith("(Hi)") and hi.address + 1 == address, f"line {i + 1}"
            assert snake_name(hi.definition) == snake_name(definition), f"line {i + 1}"
            assert hi.access == access, f"line {i + 1}"
            hi.words = 2
            continue
        rows.append(ManualRow(address, definition, access, 1, i + 1))
    for row in rows:  # every (Hi) found its (Lo)
        assert row.definition.endswith("(Hi)") == (row.words == 2), f"line {row.line}"
    return rows


@pytest.fixture(scope="module")
def manual_rows() -> list[ManualRow]:
    if not MANUALS.is_dir():
        pytest.skip(f"vendor manuals folder {MANUALS} is absent")
    if not MANUAL_EN.is_file():
        pytest.skip(f"{MANUAL_EN.name} is absent from {MANUALS}")
    return _chapter4_rows(MANUAL_EN.read_text(encoding="utf-8"))


def test_every_manual_register_present(manual_rows: list[ManualRow]) -> None:
    assert len(manual_rows) == 60  # chapter 4 of v1.6: 60 registers / pairs
    for row in manual_rows:
        where = f"manual line {row.line}: 0x{row.address:04X} {row.definition}"
        reg = EROB_MODBUS[row.address]
        assert reg.name == snake_name(row.definition), where
        assert reg.access is ACCESS[row.access], where
        assert reg.words == row.words, where
        assert MANUAL_DEFINITIONS[reg.name] == row.definition, where


def test_table_is_chapter4_plus_0x00d8(manual_rows: list[ManualRow]) -> None:
    extra = {r.address for r in EROB_MODBUS} - {row.address for row in manual_rows}
    assert extra == {0x00D8}


def test_torque_mode_max_speed_from_example() -> None:
    reg = EROB_MODBUS[0x00D8]
    assert reg.name == "torque_control_mode_max_speed"
    assert (reg.type, reg.access, reg.unit) == ("int32", Access.RW, "count/s")
    assert "DOC-EROB-EN-2" in reg.description
    assert EROB_MODBUS.owner(0x00D9) is reg
    # 5.3.2 step 3 (corrected frame): 01 10 00 D8 00 02 04 00 00 00 00
    assert EROB_MODBUS.encode_block({"torque_control_mode_max_speed": 0}) == (0x00D8, [0, 0])


# ---------------------------------------------------------------------- example names


@pytest.mark.parametrize(
    ("definition", "name", "address"),
    [
        ("Enable the Motor", "enable_the_motor", 0x00F0),
        ("Max. Speed (Hi)", "max_speed", 0x00B5),
        ("Status of Achieving Position", "status_of_achieving_position", 0x0063),
        ("Modbus Communication Timeout Duration.", "modbus_communication_timeout_duration", 0x0002),
        ("Struck Current (Hi)", "struck_current", 0x00C5),
    ],
)
def test_example_names_resolve(definition: str, name: str, address: int) -> None:
    assert snake_name(definition) == name
    assert EROB_MODBUS[name].address == address
    assert EROB_MODBUS[address].name == name


def test_lo_word_address_is_rejected() -> None:
    with pytest.raises(RegisterError, match="second word of actual_position"):
        EROB_MODBUS[0x0067]


# ------------------------------------------------------------------------------- codecs


@pytest.mark.parametrize(
    ("name", "value", "words"),
    [
        ("modbus_address", 2, (0x0002,)),
        ("position_loop_gain", 0xFFFF, (0xFFFF,)),
        ("part_of_power_temperature", -20, (0xFFEC,)),
        ("part_of_power_temperature", 150, (0x0096,)),
        ("target_speed", -10000, (0xFFFF, 0xD8F0)),
        ("target_absolute_position", 500000, (0x0007, 0xA120)),  # 5.1.1.2 step 9
        ("profile_speed", 10000, (0x0000, 0x2710)),  # 5.1.1.2 step 6
        ("target_current", 1000, (0x0000, 0x03E8)),  # 5.3.2 step 6
        ("actual_position", -0x80000000, (0x8000, 0x0000)),
        ("actual_position", 0x7FFFFFFF, (0x7FFF, 0xFFFF)),
    ],
)
def test_round_trip(name: str, value: int, words: tuple[int, ...]) -> None:
    reg = EROB_MODBUS[name]
    assert reg.to_words(value) == words
    assert reg.from_words(words) == value


def test_int32_out_of_range_rejected() -> None:
    with pytest.raises(CommandError):
        EROB_MODBUS["target_speed"].to_words(0x80000000)
    with pytest.raises(CommandError):
        EROB_MODBUS["enable_the_motor"].to_words(2)


def test_status_block_decode() -> None:
    first, count = EROB_MODBUS.span("error_code", "part_of_power_temperature")
    assert (first, count) == (STATUS_BLOCK_START, STATUS_BLOCK_WORDS) == (0x0060, 25)
    words = [0] * STATUS_BLOCK_WORDS

    def put(reg: Register, value: int) -> None:
        i = reg.address - STATUS_BLOCK_START
        words[i : i + reg.words] = reg.to_words(value)

    put(EROB_MODBUS["motion_status"], MotionStatus.MOVING)
    put(EROB_MODBUS["status_of_achieving_position"], AchieveStatus.TARGET_REACHED)
    put(EROB_MODBUS["actual_position"], -3 * COUNTS_PER_REV // 4)
    put(EROB_MODBUS["current_speed"], 20950)
    put(EROB_MODBUS["bus_voltage"], 48000)
    put(EROB_MODBUS["part_of_power_temperature"], -5)
    words[0x0062 - STATUS_BLOCK_START] = 0xBEEF  # gap word: ignored

    out = EROB_MODBUS.decode_block(STATUS_BLOCK_START, words)
    assert out["actual_position"] == -393216
    assert out["motion_status"] == MotionStatus.MOVING
    assert out["status_of_achieving_position"] == AchieveStatus.TARGET_REACHED
    assert out["current_speed"] == 20950
    assert out["bus_voltage"] == 48000
    assert out["part_of_power_temperature"] == -5
    assert out["error_code"] == 0
    assert set(out) == {r.name for r in EROB_MODBUS
                        if STATUS_BLOCK_START <= r.address <= 0x0078}


def test_manual_reply_decodes() -> None:
    # 5.1.1.2 step 12 reply data 00 00 27 05 -> current speed 9989 count/s
    assert EROB_MODBUS["current_speed"].from_words((0x0000, 0x2705)) == 9989
    # 5.3.2 step 9 reply data 02 3B 3A 67 -> actual position
    assert EROB_MODBUS.decode_block(0x0066, [0x023B, 0x3A67]) == {"actual_position": 0x023B3A67}


# -------------------------------------------------------------------------------- enums


def test_enums() -> None:
    assert [int(m) for m in OperationMode] == [1, 2, 3]
    assert (MotionMode.CONTINUOUS, MotionMode.ABSOLUTE, MotionMode.REPETITIVE) == (0, 1, 2)
    assert int(MotionStatus.STOP_REPETITIVE) == 3
    assert [int(m) for m in AchieveStatus] == [0, 1, 2, 3, 4]
    assert [b.bps for b in BaudRate] == [9600, 19200, 38400, 115200]
    assert BaudRate.from_bps(115200) is BaudRate.B115200
    with pytest.raises(ValueError):
        BaudRate.from_bps(57600)
    assert COUNTS_PER_REV == 2**19
    baud = EROB_MODBUS["modbus_baud_rate"]
    assert (baud.minimum, baud.maximum) == (min(BaudRate), max(BaudRate))
    assert (EROB_MODBUS["operation_mode"].minimum, EROB_MODBUS["operation_mode"].maximum) == (
        min(OperationMode), max(OperationMode))


def test_block_decode_in_one_struct_call_equals_register_by_register() -> None:
    """decode_block's struct path gives what the register-by-register path gives (any words)."""
    import random

    from joints.devices.erob.registers import EROB_MODBUS, STATUS_BLOCK_START, STATUS_BLOCK_WORDS

    rng = random.Random(4)
    table = EROB_MODBUS
    for _ in range(200):
        words = [rng.randrange(0x10000) for _ in range(STATUS_BLOCK_WORDS)]
        fast = table.decode_block(STATUS_BLOCK_START, words)
        assert table._packed[(STATUS_BLOCK_START, STATUS_BLOCK_WORDS)] is not None
        slow = {}
        for reg in table:
            i = reg.address - STATUS_BLOCK_START
            if 0 <= i and i + reg.words <= STATUS_BLOCK_WORDS:
                slow[reg.name] = reg.from_words(words[i:i + reg.words])
        assert fast == slow and list(fast) == list(slow)
    # words out of 16 bits take the checked path (masked), as before
    assert table.decode_block(STATUS_BLOCK_START, [0x1FFFF] * STATUS_BLOCK_WORDS)["error_code"] == 0xFFFF
