"""CANopen EMCY: the CiA 301 error-code classes and error-register bits (A4).

Rule: pure data.
"""

from __future__ import annotations

from collections.abc import Mapping

__all__ = ["ERROR_REGISTER_BITS", "emcy_class_text"]

# --- EMCY ----------------------------------------------------------------------------------------

#: CiA 301 table 21 (emergency error code classes) and the CiA 402 additions most drives use.
_EMCY_CLASSES: tuple[tuple[int, int, str], ...] = (
    (0xFFFF, 0x0000, "error reset or no error"),
    (0xFFFF, 0x8110, "CAN overrun (objects lost)"),
    (0xFFFF, 0x8120, "CAN in error passive mode"),
    (0xFFFF, 0x8130, "life guard error or heartbeat error"),
    (0xFFFF, 0x8140, "recovered from bus off"),
    (0xFFFF, 0x8150, "CAN-ID collision"),
    (0xFFFF, 0x8210, "PDO not processed due to length error"),
    (0xFFFF, 0x8220, "PDO length exceeded"),
    (0xFFFF, 0x8240, "unexpected SYNC data length"),
    (0xFFFF, 0x8250, "RPDO timeout"),
    (0xFFFF, 0x8611, "following error"),
    (0xFFFF, 0x8612, "reference limit"),
    (0xFFFF, 0x7121, "motor blocked"),
    (0xFFFF, 0x2310, "continuous over current"),
    (0xFFFF, 0x3210, "DC link over-voltage"),
    (0xFFFF, 0x3220, "DC link under-voltage"),
    (0xFFFF, 0x4310, "drive temperature too high"),
    (0xFF00, 0x8100, "communication"),
    (0xFF00, 0x8200, "protocol error"),
    (0xFF00, 0x8400, "velocity speed controller"),
    (0xFF00, 0x8600, "positioning controller"),
    (0xFF00, 0x2100, "current, device input side"),
    (0xFF00, 0x2200, "current inside the device"),
    (0xFF00, 0x2300, "current, device output side"),
    (0xFF00, 0x3100, "mains voltage"),
    (0xFF00, 0x3200, "voltage inside the device"),
    (0xFF00, 0x3300, "output voltage"),
    (0xFF00, 0x4100, "ambient temperature"),
    (0xFF00, 0x4200, "device temperature"),
    (0xFF00, 0x4300, "drive temperature"),
    (0xFF00, 0x6100, "internal software"),
    (0xFF00, 0x6200, "user software"),
    (0xFF00, 0x6300, "data set"),
    (0xFF00, 0x7100, "motor"),
    (0xFF00, 0x7300, "sensor"),
    (0xFF00, 0xFF00, "device specific"),
    (0xF000, 0x1000, "generic error"),
    (0xF000, 0x2000, "current"),
    (0xF000, 0x3000, "voltage"),
    (0xF000, 0x4000, "temperature"),
    (0xF000, 0x5000, "device hardware"),
    (0xF000, 0x6000, "device software"),
    (0xF000, 0x7000, "additional modules"),
    (0xF000, 0x8000, "monitoring"),
    (0xF000, 0x9000, "external error"),
    (0xF000, 0xF000, "additional functions"),
)

#: error register (0x1001) bits, CiA 301 7.5.2.2
ERROR_REGISTER_BITS: Mapping[int, str] = {
    0: "generic error", 1: "current", 2: "voltage", 3: "temperature", 4: "communication error",
    5: "device profile specific", 6: "reserved", 7: "manufacturer specific",
}


def emcy_class_text(code: int) -> str:
    """The most specific CiA 301/402 class of an EMCY error code."""
    for mask, value, text in _EMCY_CLASSES:
        if code & mask == value:
            return text
    return "unknown error class"
