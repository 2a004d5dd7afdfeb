"""The MKS read/write-all blocks of firmware V1.0.6 (manual V1.0.9 5.7): their bytes by parameter name.

Rule: pure data. 0x46 writes and 0x47 reads the 34 configuration bytes (5.7.1/5.7.2), 0x48 reads
the 28 status bytes (5.7.3); each configuration field is a parameter of
:data:`~joints.devices.mks.params.MKS_PARAMS` (big-endian, like every MKS field), the status block
also carries 0x35's raw encoder value and the single-turn zero state. The manual's own 0x46 example (FA 01 46 02 0C 80 ... 6C)
decodes to the documented defaults of a SERVO57D (3200 mA, 16 microsteps, 38400 baud, address 1 ...).

Choices where the manual is thin: ``microsteps`` byte 0x00 means 256 (as 0x84); the 0x47 reply
carries "Reserved (FF)" where 0x46 has "setting 0 point" (``zero_mode_set_zero``): a read leaves it
out; a group address 0 is "none" (the drive's power-on value); byte 30 "Zero mode" under 0x94 is ``home_mode`` and bytes 31-32 "Zero-return current" are
``home_current`` (0x94's fields). In the 0x48 status block the raw encoder value (0x35) is 6 bytes
and the angle error 4 (the byte count 28 fixes both); the two "return to zero" bytes are 0x3B's
single-turn and non-single-turn states, of which the twin reports the one it has in both.
"""

from __future__ import annotations

from collections.abc import Mapping

from joints.devices.params import ParamSet

__all__ = ["ALL_PARAMETERS", "ALL_STATUS", "NOT_READ_BACK", "check", "pack", "unpack"]

#: 0x46/0x47: (parameter, byte offset in the data, size)
ALL_PARAMETERS: tuple[tuple[str, int, int], ...] = (
    ("work_mode", 0, 1), ("working_current", 1, 2), ("holding_current", 3, 1), ("microsteps", 4, 1),
    ("en_active_level", 5, 1), ("motor_direction", 6, 1), ("auto_screen_off", 7, 1),
    ("locked_rotor_protection", 8, 1), ("subdivision_interpolation", 9, 1), ("baud_rate", 10, 1),
    ("slave_address", 11, 1), ("group_address", 12, 1), ("slave_respond", 13, 1), ("slave_active", 14, 1),
    ("modbus_rtu", 15, 1), ("key_lock", 16, 1), ("home_trigger_level", 17, 1), ("home_direction", 18, 1),
    ("home_speed", 19, 2), ("end_limit", 21, 1), ("home_reverse_angle", 22, 4), ("home_mode", 26, 1),
    ("home_current", 27, 2), ("limit_port_remap", 29, 1), ("zero_mode", 30, 1), ("zero_mode_set_zero", 31, 1),
    ("zero_mode_speed", 32, 1), ("zero_mode_direction", 33, 1),
)
#: fields 0x47 does not report (its byte is "Reserved (FF)")
NOT_READ_BACK = frozenset({"zero_mode_set_zero"})
#: 0x48: (parameter, offset, size, signed)
ALL_STATUS: tuple[tuple[str, int, int], ...] = (
    ("motor_status", 0, 1), ("encoder_addition", 1, 6), ("real_time_speed", 7, 2), ("number_of_pulses", 9, 4),
    ("io_status", 13, 1), ("raw_encoder_value", 14, 6), ("angle_error", 20, 4), ("en_pin_status", 24, 1),
    ("single_turn_zero_status", 25, 1), ("protection_state", 26, 1), ("go_back_to_zero_status", 27, 1),
)
_SIGNED = frozenset({"encoder_addition", "real_time_speed", "number_of_pulses", "raw_encoder_value", "angle_error"})


def pack(layout: tuple[tuple[str, int, int], ...], values: Mapping[str, int], size: int) -> bytes:
    """The block's bytes for ``values`` (every field of ``layout`` must be given; microsteps 256 -> 0x00)."""
    out = bytearray(size)
    for name, offset, n in layout:
        v = int(values[name])
        if name == "microsteps" and v == 256:
            v = 0
        out[offset:offset + n] = v.to_bytes(n, "big", signed=name in _SIGNED)
    return bytes(out)


def unpack(layout: tuple[tuple[str, int, int], ...], data: bytes, *, skip: frozenset[str] = frozenset()) -> dict[str, int]:
    """The block's bytes -> {parameter: value} (microsteps 0x00 -> 256; ``skip``: fields left out)."""
    out: dict[str, int] = {}
    for name, offset, n in layout:
        if name in skip:
            continue
        v = int.from_bytes(data[offset:offset + n], "big", signed=name in _SIGNED)
        out[name] = 256 if name == "microsteps" and v == 0 else v
    return out


def check(params: ParamSet, values: Mapping[str, int]) -> None:
    """Range-check a configuration block's values (raises :class:`~joints.errors.CommandError`); a group
    address of 0 is "no group" there, as at power-on."""
    for name, value in values.items():
        if name == "group_address" and value == 0:
            continue
        params[name].check(value)
