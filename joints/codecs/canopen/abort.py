"""CANopen SDO abort codes (CiA 301 7.2.4.3.17) and their texts.

Rule: pure data.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping

from joints.errors import DeviceRejected

__all__ = ["ABORT_TEXT", "SdoAbortCode", "abort_error", "abort_text"]

# --- SDO abort codes ---------------------------------------------------------------------------


class SdoAbortCode(enum.IntEnum):
    """SDO abort codes (CiA 301 v4.2, 7.2.4.3.17)."""

    TOGGLE_BIT_NOT_ALTERNATED = 0x05030000
    TIMEOUT = 0x05040000
    COMMAND_SPECIFIER_INVALID = 0x05040001
    INVALID_BLOCK_SIZE = 0x05040002
    INVALID_SEQUENCE_NUMBER = 0x05040003
    CRC_ERROR = 0x05040004
    OUT_OF_MEMORY = 0x05040005
    UNSUPPORTED_ACCESS = 0x06010000
    READ_WRITE_ONLY = 0x06010001
    WRITE_READ_ONLY = 0x06010002
    OBJECT_DOES_NOT_EXIST = 0x06020000
    CANNOT_BE_MAPPED = 0x06040041
    PDO_LENGTH_EXCEEDED = 0x06040042
    PARAMETER_INCOMPATIBLE = 0x06040043
    INTERNAL_INCOMPATIBILITY = 0x06040047
    HARDWARE_ERROR = 0x06060000
    LENGTH_MISMATCH = 0x06070010
    LENGTH_TOO_HIGH = 0x06070012
    LENGTH_TOO_LOW = 0x06070013
    SUBINDEX_DOES_NOT_EXIST = 0x06090011
    INVALID_VALUE = 0x06090030
    VALUE_TOO_HIGH = 0x06090031
    VALUE_TOO_LOW = 0x06090032
    MAX_LESS_THAN_MIN = 0x06090036
    RESOURCE_NOT_AVAILABLE = 0x060A0023
    GENERAL_ERROR = 0x08000000
    CANNOT_STORE = 0x08000020
    CANNOT_STORE_LOCAL_CONTROL = 0x08000021
    CANNOT_STORE_DEVICE_STATE = 0x08000022
    NO_OBJECT_DICTIONARY = 0x08000023
    NO_DATA_AVAILABLE = 0x08000024


#: abort code -> its meaning (CiA 301 v4.2 table 22, our wording)
ABORT_TEXT: Mapping[int, str] = {
    SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED: "toggle bit not alternated",
    SdoAbortCode.TIMEOUT: "SDO protocol timed out",
    SdoAbortCode.COMMAND_SPECIFIER_INVALID: "client/server command specifier not valid or unknown",
    SdoAbortCode.INVALID_BLOCK_SIZE: "invalid block size (block mode only)",
    SdoAbortCode.INVALID_SEQUENCE_NUMBER: "invalid sequence number (block mode only)",
    SdoAbortCode.CRC_ERROR: "CRC error (block mode only)",
    SdoAbortCode.OUT_OF_MEMORY: "out of memory",
    SdoAbortCode.UNSUPPORTED_ACCESS: "unsupported access to an object",
    SdoAbortCode.READ_WRITE_ONLY: "attempt to read a write-only object",
    SdoAbortCode.WRITE_READ_ONLY: "attempt to write a read-only object",
    SdoAbortCode.OBJECT_DOES_NOT_EXIST: "object does not exist in the object dictionary",
    SdoAbortCode.CANNOT_BE_MAPPED: "object cannot be mapped to the PDO",
    SdoAbortCode.PDO_LENGTH_EXCEEDED: "the number and length of the objects to be mapped would exceed the PDO length",
    SdoAbortCode.PARAMETER_INCOMPATIBLE: "general parameter incompatibility",
    SdoAbortCode.INTERNAL_INCOMPATIBILITY: "general internal incompatibility in the device",
    SdoAbortCode.HARDWARE_ERROR: "access failed due to a hardware error",
    SdoAbortCode.LENGTH_MISMATCH: "data type does not match, length of service parameter does not match",
    SdoAbortCode.LENGTH_TOO_HIGH: "data type does not match, length of service parameter too high",
    SdoAbortCode.LENGTH_TOO_LOW: "data type does not match, length of service parameter too low",
    SdoAbortCode.SUBINDEX_DOES_NOT_EXIST: "sub-index does not exist",
    SdoAbortCode.INVALID_VALUE: "invalid value for parameter (download only)",
    SdoAbortCode.VALUE_TOO_HIGH: "value of parameter written too high (download only)",
    SdoAbortCode.VALUE_TOO_LOW: "value of parameter written too low (download only)",
    SdoAbortCode.MAX_LESS_THAN_MIN: "maximum value is less than minimum value",
    SdoAbortCode.RESOURCE_NOT_AVAILABLE: "resource not available: SDO connection",
    SdoAbortCode.GENERAL_ERROR: "general error",
    SdoAbortCode.CANNOT_STORE: "data cannot be transferred or stored to the application",
    SdoAbortCode.CANNOT_STORE_LOCAL_CONTROL:
        "data cannot be transferred or stored to the application because of local control",
    SdoAbortCode.CANNOT_STORE_DEVICE_STATE:
        "data cannot be transferred or stored to the application because of the present device state",
    SdoAbortCode.NO_OBJECT_DICTIONARY:
        "object dictionary dynamic generation failed or no object dictionary is present",
    SdoAbortCode.NO_DATA_AVAILABLE: "no data available",
}


def abort_text(code: int) -> str:
    return ABORT_TEXT.get(code, "abort code not defined by CiA 301 (manufacturer specific?)")


def abort_error(node: int, index: int, subindex: int, code: int) -> DeviceRejected:
    """The error for an abort received from node ``node`` (code = the abort code)."""
    return DeviceRejected(f"node {node}: SDO 0x{index:04X}:{subindex:02X} aborted with 0x{code:08X} "
                          f"({abort_text(code)})", code=code)
