"""ZLAC8015D dual-channel hub servo driver: Modbus RTU register table.

Source: "ZLAC8015D Servo Driver (Special for Hub Servo Motor) RS485 Communication Instruction"
v1.04, chapter 4 "ADDRESS DIRECTIONARY" (``../shared/manuals/zlac8015d-rs485-modbus-manual-v1.04.txt``,
an OCR text; chapter 4 is lines 778-1373), cross-checked against the parameter tables of
chapter 3 (lines 308-777), the manual's example frames (``../shared/vectors/vectors.json``,
device ``zlac8015d``) and ``ERRATA.md`` (DOC-ZLAC-1..7). Line numbers below are 1-based lines
of that text file.

Rules of this table:

* Every index printed in chapter 4 is here: the common registers 0x2000-0x201B, the left
  motor bank 0x2030-0x204A, the right motor bank 0x2060-0x207A (same layout, +0x30), the
  control parameters 0x2080-0x2091 and the read-only block 0x20A0-0x20AF. Indexes that
  chapter 4 skips (0x2041/0x2042, 0x2071/0x2072, ...) are not invented.
* A "high 16 bits"/"low 16 bits" pair is ONE ``int32`` entry at the high-word address; the
  manual types each half as I16 and its examples send the **high word first, at the lower
  address** (``01 10 20 8A 00 02 04 00 00 50 00`` = target position (Left) 20480, and
  ``FF FF B0 00`` = -20480), hence ``low_word_first=False``. "high/low 16 bits" are dropped
  from the names like "(Hi)"/"(Lo)": ``target_position_left``, ``actual_motor_position_left``.
* Names are the manual's Name column through :func:`snake_name`; "(Left)"/"(Right)" become
  ``_left``/``_right``. The motor banks print their names without a side (the side is the
  section heading "Left motor parameter"/"Right motor parameter"), so the suffix is added:
  "Encoder line" at 0x2030 -> ``encoder_line_left``, at 0x2060 -> ``encoder_line_right``.
  :data:`MANUAL_NAMES` keeps the (repaired) printed name of every entry.
* Types from the Type column: U16 -> ``uint16``, I16 -> ``int16`` (the OCR prints U16 as
  "Uul6", "ulé", "ule", "uile", "uU16", "ui6", "U6", "vte" ... and I16 as "116").
* Units are as printed, normalised: "ms", "10 ms", "r/min", "0.1 r/min", "mA", "mA/s",
  "0.1 A", "0.01 V", "counts", "10 counts", "%", "deg", "degC", "0.1 degC", "lines".
* ``default`` is the Default column as an int ("500ms" -> 500); where chapter 4 prints none,
  chapter 3 is used, else 0 (names listed in :data:`DEFAULTS_NOT_PRINTED`).
* ``persistent=True`` marks writes that are persistent or dangerous: bus settings (RS485 and
  CAN node id / baud rate), the EEPROM-store and factory-restore commands, the power-on
  enable state, and the motor-identity and protection parameters of both banks (encoder
  lines, hall offset, poles, current limits, overload, following-error and temperature
  limits, maximum speed): a wrong value there makes the motor commutate wrongly or disables
  its protection, and every RW register becomes persistent once 0x2010 stores it to EEPROM.
  The manual itself never says which registers need a restart; it only marks 0x2005/0x2006
  "Not saved". Gains, filters, ramps and set-points are not flagged.

OCR repairs and ambiguities (each is also noted at its entry):

* 0x2001 RS485 Node ID (line 786): range printed "17127" = "1~127"; default printed 4, but
  section 1 (line 5) says the default address is 1 and every example uses address 1 ->
  default 1 (ERRATA DOC-ZLAC-3).
* 0x2004 (line 797) "YO-Y1" -> Y0-Y1; 0x201A (line 983) "YO function choice" -> "Y0 ...".
* 0x2006 (line 807): value 3 is printed as a second "Reset the zero point(Right)"
  (DOC-ZLAC-4; probably both wheels).
* 0x2009 (line 816): "O: Invalid" -> 0.
* 0x200B (lines 821-827): the value numbers 2..6 of the CAN baud list are OCR'd as "o U b W N".
* 0x200C (line 829) and 0x2015 (line 969): index printed with no name, description, type,
  access or default -> ``unnamed_200c``/``unnamed_2015``, treated as read-only uint16.
* Stray Default-column numbers "800" (line 946, after 0x2013) and "150" (line 968, after
  0x2014) cannot be defaults of those enumerations (0/1 and 1..3); not assigned.
* 0x2016/0x2019 (lines 970-971, 978-979): "Bit1: Input(X0)" -> Input(X1); the output
  register 0x2019 repeats the input text -> Output(Y0)/Output(Y1) (DOC-ZLAC-6).
* 0x2018 printed "5018h" (line 976); 0x2046/0x2047 printed ">046h"/">047h" (lines
  1020/1022); 0x2048 printed "5048h" (line 1024); 0x2049 printed as a second "2045h"
  (line 1026, between 0x2048 and 0x204A); 0x2079 printed without "h" (line 1074); 0x20A1
  printed "20A1lh" (line 1205).
* Names: "ClKi" -> "Cl Ki" (lines 1004, 1047); "VI Kp/Ki/Kf" and "VIKp" -> "Vl Kp/Ki/Kf"
  (velocity loop, matching "Cl" current loop and "Pl" position loop; lines 1009-1011,
  1052-1054); "Velocity ~ smoothing factor" -> "Velocity smoothing factor" (lines 1001,
  1044); "Sofeware version" -> "Software version" (line 1197).
* 0x2043/0x2044 and 0x2073/0x2074 (lines 1014-1018, 1057-1062): range "1-250/min" -> 1..250
  r/min; 0x2044 type "vte" -> U16 and default "Lr/min" -> 1 r/min.
* 0x2086/0x2087 (line 1098): unit mA/s but default printed "300ms" -> 300 (DOC-ZLAC-5).
* 0x200F: the table says 0 = synchronous, 1 = asynchronous, the examples of section 3.2 use
  0 = asynchronous, 1 = synchronous; this table follows the EXAMPLES (DOC-ZLAC-1, :class:`SyncMode`).
* 0x20A2-0x20A4 pack both wheels into one word (high byte left, low byte right); their
  printed ranges (0-7, 0-120) are per byte, so no word range is set.
* 0x20AF (line 1368): "Software 01 connected status": the meaning of "01" is not legible.

Encoder resolution: chapter 4 gives the encoder *lines* (0x2030/0x2060, default 1024) but
never counts per revolution. With the usual x4 quadrature decoding that is 4096 counts/rev,
which agrees with the manual's numbers: the position-following-error threshold default is
409 x 10 counts (about one turn) and the position examples move 20480 = 5 x 4096 counts.
"""

from __future__ import annotations

import enum
import re

from joints.devices.quirks import ZLAC_SYNC_FLAG_AS_EXAMPLES
from joints.devices.registers import Access, Register, RegisterTable, snake_name

__all__ = [
    "CAN_BAUD_RATES",
    "COUNTS_PER_REV",
    "DEFAULTS_NOT_PRINTED",
    "ENCODER_LINES",
    "MANUAL_NAMES",
    "RS485_BAUD_RATES",
    "STATUS_BLOCK_START",
    "STATUS_BLOCK_WORDS",
    "UNNAMED",
    "ZLAC8015D",
    "ControlMode",
    "ControlWord",
    "Fault",
    "QuickStopBehaviour",
    "SyncMode",
    "describe",
    "is_synchronous",
    "split_left_right",
    "sync_flag",
]

#: Encoder lines per motor revolution (default of 0x2030/0x2060).
ENCODER_LINES = 1024
#: Position counts per motor revolution: lines x 4 (quadrature; not stated by the manual).
COUNTS_PER_REV = ENCODER_LINES * 4

#: 0x2002 code -> RS485 bit/s.
RS485_BAUD_RATES: dict[int, int] = {
    0: 256000, 1: 128000, 2: 115200, 3: 57600, 4: 38400, 5: 19200, 6: 9600,
}
#: 0x200B code -> CAN bit/s.
CAN_BAUD_RATES: dict[int, int] = {
    0: 1_000_000, 1: 500_000, 2: 250_000, 3: 125_000, 4: 100_000, 5: 50_000, 6: 25_000,
}


class ControlWord(enum.IntEnum):
    """Values of ``control_word`` (0x200E)."""

    QUICK_STOP = 0x05
    CLEAR_FAULT = 0x06
    STOP = 0x07
    ENABLE = 0x08
    START_SYNC = 0x10  #: start both wheels (position mode, synchronous control)
    START_LEFT = 0x11  #: start the left wheel (position mode, asynchronous control)
    START_RIGHT = 0x12  #: start the right wheel (position mode, asynchronous control)


class ControlMode(enum.IntEnum):
    """Values of ``control_mode`` (0x200D)."""

    UNDEFINED = 0
    RELATIVE_POSITION = 1
    ABSOLUTE_POSITION = 2
    VELOCITY = 3
    TORQUE = 4


class SyncMode(enum.IntEnum):
    """Values of ``synchronous_asynchronous_control_status`` (0x200F), as the EXAMPLES use them.

    The chapter-3/4 tables print the opposite (0 = synchronous, 1 = asynchronous); the
    examples of section 3.2 write 0 for "Asynchronous control" and 1 for "Synchronous
    control" and pair them with Start(Left)/(Right) and Start(Synchronous) respectively
    (ERRATA DOC-ZLAC-1).
    """

    ASYNCHRONOUS = 0
    SYNCHRONOUS = 1


def sync_flag(synchronous: bool, quirks: frozenset[str]) -> int:
    """The 0x200F value for synchronous / asynchronous control on a firmware with ``quirks``
    (:mod:`joints.devices.quirks`: with ``zlac-sync-flag-as-examples`` the examples' values
    (:class:`SyncMode`), without it the register table's: 0 = synchronous, 1 = asynchronous)."""
    if ZLAC_SYNC_FLAG_AS_EXAMPLES in quirks:
        return int(SyncMode.SYNCHRONOUS if synchronous else SyncMode.ASYNCHRONOUS)
    return 0 if synchronous else 1


def is_synchronous(flag: int, quirks: frozenset[str]) -> bool:
    """Whether a 0x200F value means synchronous control on a firmware with ``quirks`` (see :func:`sync_flag`)."""
    return flag == sync_flag(True, quirks)


class QuickStopBehaviour(enum.IntEnum):
    """Values of ``quick_stop_control`` (0x2011): what the drive does on a quick-stop command."""

    STOP = 5
    QUICK_STOP_WITH_DECELERATION = 6  #: ramp down with the quick-stop deceleration time
    QUICK_STOP_WITHOUT_DECELERATION = 7


class Fault(enum.IntFlag):
    """Fault bits of ``error_code_left``/``error_code_right`` (0x20A5/0x20A6); 0 = none."""

    OVER_VOLTAGE = 0x0001
    UNDER_VOLTAGE = 0x0002
    OVER_CURRENT = 0x0004
    OVER_LOAD = 0x0008
    CURRENT_FOLLOWING_ERROR = 0x0010
    POSITION_FOLLOWING_ERROR = 0x0020
    VELOCITY_FOLLOWING_ERROR = 0x0040
    REFERENCE_VOLTAGE_ERROR = 0x0080
    EEPROM_ERROR = 0x0100
    HALL_ERROR = 0x0200
    MOTOR_OVER_TEMPERATURE = 0x0400


#: The manual's text of every fault bit (lines 762-772 and 1260-1293).
_FAULT_TEXT: dict[int, str] = {
    0x0001: "Over voltage",
    0x0002: "Under voltage",
    0x0004: "Over current",
    0x0008: "Over load",
    0x0010: "Current following error",
    0x0020: "Position following error",
    0x0040: "Velocity following error",
    0x0080: "Reference voltage error",
    0x0100: "EEPROM error",
    0x0200: "Hall error",
    0x0400: "Motor temperature over temperature",
}


def describe(bits: int) -> list[str]:
    """The manual's text for every set fault bit, lowest bit first ([] for 0 = "None").

    Bits the manual does not document come out as ``"undocumented fault bit 0x0800"``.
    """
    out: list[str] = []
    value = int(bits) & 0xFFFF
    for i in range(16):
        bit = 1 << i
        if value & bit:
            out.append(_FAULT_TEXT.get(bit, f"undocumented fault bit 0x{bit:04X}"))
    return out


def split_left_right(word: int) -> tuple[int, int]:
    """(left, right) of a packed two-wheel word (0x20A2-0x20A4: high byte left, low byte right)."""
    return (word >> 8) & 0xFF, word & 0xFF


#: Printed Name column (OCR-repaired, side added for the motor banks, Hi row for pairs), by name.
MANUAL_NAMES: dict[str, str] = {}
#: Entries whose chapter-4 row has no name (index only): name -> manual line.
UNNAMED: dict[str, int] = {}
#: Entries whose Default column is not printed in chapter 4 or chapter 3 (``default`` is 0).
DEFAULTS_NOT_PRINTED: set[str] = set()

_R, _RW = Access.R, Access.RW
_HALF = re.compile(r"\s*\b(high|low) 16 bits\b", re.IGNORECASE)


def _name(printed: str) -> str:
    """Printed name -> register name ("high/low 16 bits" dropped like "(Hi)"/"(Lo)")."""
    return snake_name(_HALF.sub("", printed))


def _reg(
    address: int,
    printed: str,
    type: str = "uint16",
    access: Access = Access.RW,
    unit: str = "",
    description: str = "",
    *,
    minimum: int | None = None,
    maximum: int | None = None,
    default: int | None = 0,
    persistent: bool = False,
    name: str | None = None,
) -> Register:
    """One entry; ``default=None`` means "not printed" (stored as 0, listed in DEFAULTS_NOT_PRINTED)."""
    if name is None:
        name = _name(printed)
        MANUAL_NAMES[name] = printed
    if default is None:
        DEFAULTS_NOT_PRINTED.add(name)
        default = 0
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


def _unnamed(address: int, line: int) -> Register:
    name = f"unnamed_{address:04x}"
    UNNAMED[name] = line
    return _reg(
        address, "", "uint16", _R, "",
        f"Index {address:04X}h is printed in chapter 4 (line {line}) without name, description, "
        "type, access or default (lost in the OCR text). Kept so the index is known; treated "
        "as read-only and never written.",
        default=None, name=name,
    )


def _bank(
    offset: int,
    printed: str,
    type: str = "uint16",
    unit: str = "",
    description: str = "",
    *,
    minimum: int | None = None,
    maximum: int | None = None,
    default: int = 0,
    persistent: bool = False,
) -> list[Register]:
    """The same motor parameter in the left (0x2030 + offset) and right (0x2060 + offset) bank."""
    return [
        _reg(base + offset, f"{printed}({side})", type, _RW, unit,
             f"{side} motor: {description}",
             minimum=minimum, maximum=maximum, default=default, persistent=persistent)
        for base, side in ((0x2030, "Left"), (0x2060, "Right"))
    ]


_GAIN = "Control-loop tuning parameter (no unit given)."

_REGISTERS: list[Register] = [
    # ---- Common constants for left and right motors (lines 781-986) ---------------------
    _reg(0x2000, "Communication offline time", "uint16", _RW, "ms",
         "Host communication watchdog: the drive treats the host as offline after this "
         "time without communication.",
         minimum=0, maximum=32767, default=1000),
    # line 786: range "17127" is OCR for "1~127"; default printed 4, but section 1 (line 5)
    # says the default address is 1 and all examples use 1 (DOC-ZLAC-3) -> 1.
    _reg(0x2001, "RS485 Node ID", "uint16", _RW, "",
         "Modbus slave address, 1..127 (section 1 says 0-127; 0 is the Modbus broadcast "
         "address). Default 1 per section 1 and the examples; chapter 4 prints 4 "
         "(ERRATA DOC-ZLAC-3). Changes the bus address.",
         minimum=1, maximum=127, default=1, persistent=True),
    _reg(0x2002, "RS485 Baud Rate", "uint16", _RW, "",
         "Baud-rate code: 0 = 256000, 1 = 128000, 2 = 115200 (default), 3 = 57600, "
         "4 = 38400, 5 = 19200, 6 = 9600 bit/s (see RS485_BAUD_RATES). Changes the bus speed.",
         minimum=0, maximum=6, default=2, persistent=True),
    _reg(0x2003, "Input signal status", "uint16", _R, "",
         "Level of the 2 digital inputs: bit0 = X0, bit1 = X1."),
    # line 797: "YO-Y1" -> Y0-Y1, "Bitl" -> Bit1.
    _reg(0x2004, "Out signal status", "uint16", _R, "",
         "Level of the 2 digital outputs: bit0 = Y0, bit1 = Y1."),
    _reg(0x2005, "Clear feedback position", "uint16", _RW, "",
         "Write 1 to clear the feedback position (0x20A7-0x20AA) in profile position mode; "
         "0 = no action. Not saved.",
         minimum=0, maximum=1),
    # line 807: value 3 printed as a second "Reset the zero point(Right)" (DOC-ZLAC-4).
    _reg(0x2006, "In absolute position control, reset the zero point", "uint16", _RW, "",
         "Absolute position mode: make the current position the zero point. 0 = no action, "
         "1 = left, 2 = right, 3 = printed as 'right' again, presumably both wheels "
         "(ERRATA DOC-ZLAC-4). Not saved.",
         minimum=0, maximum=3),
    _reg(0x2007, "Driver state", "uint16", _RW, "",
         "Whether the drive enables the motors at power-on: 0 = stopped, 1 = enabled. "
         "Flagged persistent: once stored (0x2010) the motors energise at every power-up.",
         minimum=0, maximum=1, persistent=True),
    _reg(0x2008, "Maximum motor speed", "uint16", _RW, "r/min",
         "Motor speed limit. Flagged persistent: protection limit.",
         minimum=1, maximum=1000, default=1000, persistent=True),
    # line 816: "O: Invalid" -> 0.
    _reg(0x2009, "Register parameter settings", "uint16", _RW, "",
         "Write 1 to restore the factory settings (all parameters); 0 = no action.",
         minimum=0, maximum=1, persistent=True),
    _reg(0x200A, "CAN Node ID", "uint16", _RW, "",
         "CANopen node id (the CAN interface is not used over Modbus).",
         minimum=1, maximum=127, default=1, persistent=True),
    # lines 821-827: codes 2..6 of the list are OCR'd as "o U b W N".
    _reg(0x200B, "CAN Baud rate", "uint16", _RW, "",
         "CAN bit-rate code: 0 = 1000, 1 = 500 (default), 2 = 250, 3 = 125, 4 = 100, "
         "5 = 50, 6 = 25 kbit/s (see CAN_BAUD_RATES).",
         minimum=0, maximum=6, default=1, persistent=True),
    _unnamed(0x200C, 829),
    # default not printed in chapter 4; chapter 3 (lines 317, 414, 653) gives 0.
    _reg(0x200D, "Control mode", "uint16", _RW, "",
         "Operating mode: 0 = undefined, 1 = relative position, 2 = absolute position, "
         "3 = velocity, 4 = torque (see ControlMode).",
         minimum=0, maximum=4),
    # default 0 from chapter 3 (lines 314, 405).
    _reg(0x200E, "Control word", "uint16", _RW, "",
         "Command: 0x05 = quick stop, 0x06 = clear fault, 0x07 = stop, 0x08 = enable, "
         "0x10 = start both wheels (synchronous, position mode), 0x11 = start left, "
         "0x12 = start right (see ControlWord). The default 0 is the power-on read-back, "
         "not a command.",
         minimum=0x05, maximum=0x12),
    # DOC-ZLAC-1: table (lines 880-882, 410-412) says 0 = synchronous, 1 = asynchronous; the
    # section 3.2 examples (lines 460-462, 566) use 0 = asynchronous, 1 = synchronous.
    _reg(0x200F, "Synchronous/asynchronous control status", "uint16", _RW, "",
         "Position-mode wheel coupling, following the manual's EXAMPLES: 0 = asynchronous "
         "(wheels started separately with 0x11/0x12), 1 = synchronous (both started with "
         "0x10). The register table prints the opposite (0 = synchronous, 1 = asynchronous); "
         "the examples are internally consistent (ERRATA DOC-ZLAC-1). See SyncMode.",
         minimum=0, maximum=1),
    _reg(0x2010, "Whether store RW register to EEPROM", "uint16", _RW, "",
         "Write 1 to store all RW registers to EEPROM (they then survive power cycles); "
         "0 = no action.",
         minimum=0, maximum=1, default=None, persistent=True),
    _reg(0x2011, "Quick stop control", "uint16", _RW, "",
         "Reaction to the quick-stop command: 5 = stop, 6 = quick stop with the quick-stop "
         "deceleration time, 7 = quick stop without deceleration (see QuickStopBehaviour).",
         minimum=5, maximum=7, default=None),
    _reg(0x2012, "Stop control", "uint16", _RW, "",
         "Reaction to the stop command: 0 = none, 1 = stop (switch to 'ready to switch on').",
         minimum=0, maximum=1, default=None),
    # line 946: stray "800" in the Default column here; not a valid value, not assigned.
    _reg(0x2013, "Disable control", "uint16", _RW, "",
         "Reaction to the disable command: 0 = none, 1 = stop (switch to 'switched on').",
         minimum=0, maximum=1, default=None),
    # line 968: stray "150" in the Default column here; not a valid value, not assigned.
    _reg(0x2014, "Halt control", "uint16", _RW, "",
         "Reaction to the halt command, operation stays enabled: 1 = stop, 2 = quick stop "
         "with deceleration time, 3 = quick stop without deceleration time.",
         minimum=1, maximum=3, default=None),
    _unnamed(0x2015, 969),
    # lines 970-971: "Bitl: Input(X0)" -> Bit1: Input(X1) (DOC-ZLAC-6).
    _reg(0x2016, "Input effective level", "uint16", _RW, "",
         "Active level of the inputs, bit0 = X0, bit1 = X1: 0 = default (high level), "
         "1 = reversed (low level).",
         minimum=0, maximum=3),
    _reg(0x2017, "X0 function choice", "uint16", _RW, "",
         "Function of input X0: 0 = none, 1-8 = not used (NC), 9 = quick stop.",
         minimum=0, maximum=9, default=9),
    # line 976: index printed "5018h".
    _reg(0x2018, "X1 function choice", "uint16", _RW, "",
         "Function of input X1: 0 = none, 1-8 = not used (NC), 9 = quick stop.",
         minimum=0, maximum=9),
    # lines 978-979: printed "Bit0: Input(X0), Bitl: Input(X0)" (DOC-ZLAC-6) -> Y0/Y1.
    _reg(0x2019, "Output effective level", "uint16", _RW, "",
         "Active level of the outputs, bit0 = Y0, bit1 = Y1: 0 = default (high level), "
         "1 = reversed (low level). The manual prints the input text 'Input(X0)' for both "
         "bits (ERRATA DOC-ZLAC-6).",
         minimum=0, maximum=3),
    # line 983: "YO function choice" -> Y0.
    _reg(0x201A, "Y0 function choice", "uint16", _RW, "",
         "Function of output Y0: brake output, 0 = open brake, 1 = close brake (the value "
         "list is printed once for 0x201A/0x201B).",
         minimum=0, maximum=1),
    _reg(0x201B, "Y1 function choice", "uint16", _RW, "",
         "Function of output Y1: brake output, 0 = open brake, 1 = close brake.",
         minimum=0, maximum=1),
    # ---- Left motor parameter 0x2030.. (lines 987-1029), right 0x2060.. (lines 1030-1078) ----
    *_bank(0x00, "Encoder line", "uint16", "lines",
           "encoder lines per revolution (counts = lines x 4, see COUNTS_PER_REV). Motor "
           "identity parameter.",
           minimum=0, maximum=4096, default=1024, persistent=True),
    *_bank(0x01, "Hall offset angle", "int16", "deg",
           "hall sensor offset angle. Motor identity parameter (commutation).",
           minimum=-360, maximum=360, persistent=True),
    *_bank(0x02, "Overload factor", "uint16", "%",
           "overload factor. Protection limit.",
           minimum=0, maximum=300, default=200, persistent=True),
    *_bank(0x03, "Rated current", "uint16", "0.1 A",
           "rated (continuous) current. Protection limit.",
           minimum=0, maximum=150, default=150, persistent=True),
    *_bank(0x04, "Maximum current", "uint16", "0.1 A",
           "peak current limit. Protection limit.",
           minimum=0, maximum=300, default=300, persistent=True),
    *_bank(0x05, "Overload protection time", "uint16", "10 ms",
           "time the overload may last before the drive faults. Protection limit.",
           minimum=0, maximum=6553, default=300, persistent=True),
    *_bank(0x06, "Position following error threshold", "uint16", "10 counts",
           "position following error that raises the fault (default 409 x 10 counts, about "
           "one turn). Protection limit.",
           minimum=1, maximum=6553, default=409, persistent=True),
    # lines 1001/1044: "Velocity ~ smoothing factor" ("~" is OCR junk).
    *_bank(0x07, "Velocity smoothing factor", "uint16", "",
           "velocity command smoothing factor.",
           minimum=0, maximum=30000, default=1000),
    *_bank(0x08, "Cl Kp", "uint16", "", "current loop proportional gain. " + _GAIN,
           minimum=0, maximum=30000, default=600),
    # lines 1004/1047: "ClKi" -> "Cl Ki".
    *_bank(0x09, "Cl Ki", "uint16", "", "current loop integral gain. " + _GAIN,
           minimum=0, maximum=30000, default=300),
    *_bank(0x0A, "Feedforward output smoothing factor", "uint16", "",
           "feedforward output smoothing factor.",
           minimum=0, maximum=30000, default=100),
    *_bank(0x0B, "Torque output smoothing factor", "uint16", "",
           "torque output smoothing factor.",
           minimum=0, maximum=30000, default=100),
    # lines 1009-1011, 1052-1054: "VI Kp/Ki/Kf", "VIKp" -> "Vl" (velocity loop; cf. Cl, Pl).
    *_bank(0x0C, "Vl Kp", "uint16", "", "velocity loop proportional gain. " + _GAIN,
           minimum=0, maximum=30000, default=500),
    *_bank(0x0D, "Vl Ki", "uint16", "", "velocity loop integral gain. " + _GAIN,
           minimum=0, maximum=30000, default=100),
    *_bank(0x0E, "Vl Kf", "uint16", "", "velocity loop feedforward gain. " + _GAIN,
           minimum=0, maximum=30000, default=500),
    *_bank(0x0F, "Pl Kp", "uint16", "", "position loop proportional gain. " + _GAIN,
           minimum=0, maximum=30000, default=100),
    *_bank(0x10, "Pl Kf", "uint16", "", "position loop feedforward gain. " + _GAIN,
           minimum=0, maximum=30000, default=50),
    # 0x2041/0x2042 and 0x2071/0x2072 are not in chapter 4.
    # lines 1016/1059: range "1-250/min" -> 1..250 r/min.
    *_bank(0x13, "Initial velocity(Velocity mode)", "uint16", "r/min",
           "initial (start) velocity in velocity mode.",
           minimum=1, maximum=250, default=1),
    # line 1018: type "vte" -> U16, default "Lr/min" -> 1 r/min; range as above.
    *_bank(0x14, "Initial velocity(Position mode)", "uint16", "r/min",
           "initial (start) velocity in position mode.",
           minimum=1, maximum=250, default=1),
    *_bank(0x15, "Poles of motor", "uint16", "",
           "motor poles (default 15, an odd number: presumably pole pairs). Motor identity "
           "parameter (commutation).",
           minimum=4, maximum=64, default=15, persistent=True),
    # line 1020: index printed ">046h"; unit "0.1° C".
    *_bank(0x16, "Over temperature threshold", "uint16", "0.1 degC",
           "motor over-temperature fault threshold (default 80.0 degC). Protection limit.",
           minimum=0, maximum=1200, default=800, persistent=True),
    # lines 1022/1024/1026: left indexes printed ">047h", "5048h" and a second "2045h"
    # (= 0x2049, between 0x2048 and 0x204A); line 1074: right 0x2079 printed "2079".
    *_bank(0x17, "Velocity observer coefficient 1", "uint16", "",
           "velocity observer coefficient 1.", minimum=0, maximum=30000, default=1000),
    *_bank(0x18, "Velocity observer coefficient 2", "uint16", "",
           "velocity observer coefficient 2.", minimum=0, maximum=30000, default=750),
    *_bank(0x19, "Velocity observer coefficient 3", "uint16", "",
           "velocity observer coefficient 3.", minimum=0, maximum=30000, default=350),
    *_bank(0x1A, "Velocity observer coefficient 4", "uint16", "",
           "velocity observer coefficient 4.", minimum=0, maximum=30000, default=1000),
    # ---- Control parameters (lines 1079-1191) ----------------------------------------------
    _reg(0x2080, "Acceleration time(Left)", "uint16", _RW, "ms",
         "Left wheel: acceleration ramp time: the time to reach the commanded speed (the manual gives "
         "no reference speed; driver and emulator both read it so).",
         minimum=0, maximum=32767, default=500),
    _reg(0x2081, "Acceleration time(Right)", "uint16", _RW, "ms",
         "Right wheel: acceleration ramp time.",
         minimum=0, maximum=32767, default=500),
    _reg(0x2082, "Deceleration time(Left)", "uint16", _RW, "ms",
         "Left wheel: deceleration ramp time.",
         minimum=0, maximum=32767, default=500),
    _reg(0x2083, "Deceleration time(Right)", "uint16", _RW, "ms",
         "Right wheel: deceleration ramp time.",
         minimum=0, maximum=32767, default=500),
    _reg(0x2084, "Deceleration time of quick stop(Left)", "uint16", _RW, "ms",
         "Left wheel: deceleration time used by a quick stop.",
         minimum=0, maximum=32767, default=10),
    _reg(0x2085, "Deceleration time of quick stop(Right)", "uint16", _RW, "ms",
         "Right wheel: deceleration time used by a quick stop.",
         minimum=0, maximum=32767, default=10),
    # line 1098: default printed "300ms" although the unit is mA/s (DOC-ZLAC-5) -> 300.
    _reg(0x2086, "Torque rate(Left)", "uint16", _RW, "mA/s",
         "Left wheel: torque (current) slope in torque mode. Default printed '300ms' "
         "(ERRATA DOC-ZLAC-5).",
         default=300),
    _reg(0x2087, "Torque rate(Right)", "uint16", _RW, "mA/s",
         "Right wheel: torque (current) slope in torque mode. Default printed '300ms' "
         "(ERRATA DOC-ZLAC-5).",
         default=300),
    _reg(0x2088, "Target velocity(Left)", "int16", _RW, "r/min",
         "Left wheel: velocity set-point in velocity mode (negative = reverse; -100 r/min "
         "is sent as 0xFF9C).",
         minimum=-3000, maximum=3000),
    _reg(0x2089, "Target velocity(Right)", "int16", _RW, "r/min",
         "Right wheel: velocity set-point in velocity mode.",
         minimum=-3000, maximum=3000),
    # lines 1106-1121: Hi/Lo rows "Target position high/low 16 bits(Left)", each I16; the
    # examples (lines 520, 533, 623) send the high word first. Relative moves allow
    # -0x7FFFFFFF..0x7FFFFFFF, absolute ones -0x3FFFFFFF..0x3FFFFFFF ("OX" = 0x, "Relativ").
    _reg(0x208A, "Target position high 16 bits(Left)", "int32", _RW, "counts",
         "Left wheel: position set-point (0x208A high word, 0x208B low word); relative "
         "mode -0x7FFFFFFF..0x7FFFFFFF, absolute mode -0x3FFFFFFF..0x3FFFFFFF. Started "
         "with control word 0x11 (asynchronous) or 0x10 (synchronous).",
         minimum=-0x7FFFFFFF, maximum=0x7FFFFFFF),
    _reg(0x208C, "Target position high 16 bits(Right)", "int32", _RW, "counts",
         "Right wheel: position set-point (0x208C high word, 0x208D low word); relative "
         "mode -0x7FFFFFFF..0x7FFFFFFF, absolute mode -0x3FFFFFFF..0x3FFFFFFF. Started "
         "with control word 0x12 (asynchronous) or 0x10 (synchronous).",
         minimum=-0x7FFFFFFF, maximum=0x7FFFFFFF),
    _reg(0x208E, "Target speed(Left)", "uint16", _RW, "r/min",
         "Left wheel: cruise speed of position-mode moves.",
         minimum=1, maximum=1000, default=120),
    _reg(0x208F, "Target speed(Right)", "uint16", _RW, "r/min",
         "Right wheel: cruise speed of position-mode moves.",
         minimum=1, maximum=1000, default=120),
    _reg(0x2090, "Target torque(Left)", "int16", _RW, "mA",
         "Left wheel: current (torque) set-point in torque mode (negative = reverse).",
         minimum=-30000, maximum=30000),
    # default not printed in chapter 4 (line 1191); chapter 3 (line 658) gives 0.
    _reg(0x2091, "Target torque(Right)", "int16", _RW, "mA",
         "Right wheel: current (torque) set-point in torque mode (negative = reverse).",
         minimum=-30000, maximum=30000),
    # ---- Read only parameters (lines 1193-1369) -------------------------------------------
    # line 1197: "Sofeware version" -> Software version.
    _reg(0x20A0, "Software version", "uint16", _R, "",
         "Firmware version of the drive.",
         default=None),
    # line 1205: index printed "20A1lh".
    _reg(0x20A1, "DC voltage", "uint16", _R, "0.01 V",
         "DC bus (supply) voltage.",
         default=None),
    _reg(0x20A2, "Motor state", "uint16", _R, "",
         "Both wheels: high byte = left, low byte = right; 0 = stopped, 1 = running "
         "(see split_left_right).",
         default=None),
    _reg(0x20A3, "Hall state", "uint16", _R, "",
         "Both wheels' hall sensor state 0..7: high byte = left, low byte = right.",
         default=None),
    _reg(0x20A4, "Motor temperature", "uint16", _R, "degC",
         "Both motors' temperature 0..120 degC: high byte = left, low byte = right.",
         default=None),
    _reg(0x20A5, "Error code(Left)", "uint16", _R, "",
         "Left motor fault bits (see Fault/describe): 0x0001 over voltage, 0x0002 under "
         "voltage, 0x0004 over current, 0x0008 over load, 0x0010 current following error, "
         "0x0020 position following error, 0x0040 velocity following error, 0x0080 "
         "reference voltage error, 0x0100 EEPROM error, 0x0200 hall error, 0x0400 motor "
         "over temperature; 0 = none. Cleared with control word 0x06.",
         default=None),
    _reg(0x20A6, "Error code(Right)", "uint16", _R, "",
         "Right motor fault bits, same coding as error_code_left (see Fault/describe).",
         default=None),
    # lines 1338-1355: Hi/Lo rows "Actual motor position high/low 16 bits(Left)", each I16.
    _reg(0x20A7, "Actual motor position high 16 bits(Left)", "int32", _R, "counts",
         "Left wheel: measured position (0x20A7 high word, 0x20A8 low word), "
         "COUNTS_PER_REV counts per motor turn.",
         minimum=-0x7FFFFFFF, maximum=0x7FFFFFFF),
    _reg(0x20A9, "Actual motor position high 16 bits(Right)", "int32", _R, "counts",
         "Right wheel: measured position (0x20A9 high word, 0x20AA low word).",
         minimum=-0x7FFFFFFF, maximum=0x7FFFFFFF),
    _reg(0x20AB, "Actual velocity(Left)", "int16", _R, "0.1 r/min",
         "Left wheel: measured velocity (100 = 10 r/min)."),
    _reg(0x20AC, "Actual velocity(Right)", "int16", _R, "0.1 r/min",
         "Right wheel: measured velocity."),
    _reg(0x20AD, "Actual torque(Left)", "int16", _R, "0.1 A",
         "Left wheel: measured current (torque).",
         minimum=-300, maximum=300),
    _reg(0x20AE, "Actual torque(Right)", "int16", _R, "0.1 A",
         "Right wheel: measured current (torque).",
         minimum=-300, maximum=300),
    # line 1368: "20AFh | Software 01 / connected status": type/default columns lost.
    _reg(0x20AF, "Software connected status", "uint16", _R, "",
         "Host software connection status; the OCR text reads 'Software 01 connected "
         "status' - value meaning and type are not legible (read as uint16).",
         default=None),
]

ZLAC8015D: RegisterTable = RegisterTable.build("zlac8015d", _REGISTERS)

#: One FC03 read of both wheels' faults, positions, velocities and torques:
#: error_code_left 0x20A5 .. actual_torque_right 0x20AE, contiguous (no gaps), 10 words.
STATUS_BLOCK_START = 0x20A5
STATUS_BLOCK_WORDS = 10
