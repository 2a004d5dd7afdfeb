"""Firmware quirks: where a device's real firmware deviates from its manual, per firmware version, as data.

Rule: data only, shared. A :class:`Quirk` names one deviation (a manual erratum the real firmware
shows, see tests/data/ERRATA.md), what the driver does about it (the workaround) and what the twin
does (the reproduction); a :class:`FirmwareProfile` is the set of quirks one firmware version has.
A joint chooses its firmware with the config key ``firmware`` (default: the family's
:data:`DEFAULT_FIRMWARE`); the driver and the twin of that joint read the same set, so a workaround
is exercised against the behaviour it works around. Code asks ``QUIRK in profile.quirks``; nothing
compares firmware names.

Known quirks

``zlac-sync-flag-as-examples`` (ZLAC8015D, ERRATA DOC-ZLAC-1): register 0x200F "synchronous/
asynchronous control" - the chapter-4 table says 0 = synchronous, 1 = asynchronous; the firmware
the manual's section 3.2 examples were captured on (and the widely used community drivers) takes
0 = asynchronous, 1 = synchronous. With the quirk the driver writes 1 for synchronous control and
the twin starts both wheels on START_SYNC only when 0x200F = 1; without it both follow the table.

Firmware features

A newer firmware may also *add* commands: a :class:`FirmwareProfile` lists them in ``features``
(names below), the driver uses them only where the profile has them and the twin answers them only
then (an older twin ignores the native command / answers Modbus exception 02, as a drive without
it would). MKS SERVO42D/57D (manuals V1.0.5 May 2024, V1.0.6 Sep 2024, V1.0.9 Nov 2025, see
docs/mks-firmware.md):

``mks-failure-replies`` (V1.0.6+): a Modbus write the drive cannot carry out is answered by FC06
with register data 0xFFFF / FC16 with register quantity 0 (before: the twin's exception 04).
``mks-all-parameters`` (V1.0.6+): 0x46 / 0x47 write / read all configuration parameters, 0x48 read
all status parameters, 0x35 raw encoder value (native protocol only).
``mks-version`` (V1.0.9): 0x40 reads calibration state, hardware and firmware version.
``mks-heartbeat`` (V1.0.9): 0x98 heartbeat protection time - the communication watchdog.
``mks-timed-returns`` (V1.0.9): 0x01 - the drive sends a read command's reply every n ms, unasked.
``mks-write-io`` (V1.0.6+): 0x36 / FC16 0x0036 write the OUT_1 / OUT_2 ports.
``mks-position-threshold`` (V1.0.8+, profile v1.0.9): 0x95 the position-reached threshold (native only).
``mks-sync`` (V1.0.8+, profile v1.0.9): 0x4A synchronization flag and 0x4B synchronous execution (Part 12.4,
native only): a run command is held (status 5) until the broadcast 0x4B starts every held one at once.
``mks-timed-speed`` (V1.0.7+, profile v1.0.9): 0xF6 / FC16 0x00F6 with a run time (10 ms units): the drive
stops by itself after it.
``mks-iap`` (V1.0.8+, profile v1.0.9): 0x50 / FC06 0x0050 IAP control: 01 enter the boot loader (IAP mode
2), 02 / 03 enter / leave the silent state (only 0x50 is heard).
``mks-pid`` (V1.0.8+, profile v1.0.9): 0x96 / 0x97 (FC16 0x0096 / 0x0097) set the vFOC / CLOSE mode PID
parameters Kp, Ki, Kd, Kv.
``mks-current-unsaved`` (V1.0.7+, profile v1.0.9): 0x83 with a trailing 00 / FC06 0x0083 with bit 15 set:
change the working current while running, not saved (status 2).
``mks-homing-status`` (V1.0.7+, profile v1.0.9): the 0x3B reply's second byte, the homing (0x91) status
(native), and FC04 0x003B read as ``status1 status2`` (Modbus; before: ``00 status``, joints.devices.mks.modbus.REVISED).
``mks-read-parameter`` (V1.0.8+, profile v1.0.9): 0x00 reads back one set command's parameter (native only).
``mks-user-id`` (V1.0.9): 0x42 read / write a user ID (native only).
``mks-pulse-divider`` (V1.0.9): 0x99 / FC16 0x0099 OUT_2 as a pulse divider output (57D only).
``mks-in1-port-mode`` (V1.0.9): 0x9F IN_1 as an input or an output (28D/35D/42D only; native only).
``mks-modbus-nolimit-home`` (V1.0.6+): FC16 0x0094, the 'noLimit' homing parameters over Modbus (native 0x94 in
every version; the V1.0.5 Part 8 has no such request).
``mks-coordinate-homing`` (V1.0.9): 0x91 with goZeroMode 01 / FC06 0x0091 = 2: run to the coordinate zero
point without a search.
``mks-single-lap-home`` (V1.0.9): 0x94 / FC16 0x0094 hm_mode 2, "single lap to zero": go home turns to the
single-turn zero point (0x9A) and resets the axis there (docs/mks-firmware.md, assumptions S1-S7).
``mks-position-error-protection`` (V1.0.6+): 0x9D / FC16 0x009D position-error protection (time window,
error count) and the En-triggered single-turn zero return; an En pulse also releases the protection.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from joints.errors import ConfigError

__all__ = ["DEFAULT_FIRMWARE", "EROB_CANOPEN_MODE_CHANGE_WHILE_ENABLED", "FIRMWARES", "MKS_ALL_PARAMETERS",
           "MKS_COORDINATE_HOMING", "MKS_CURRENT_UNSAVED",
           "MKS_FAILURE_REPLIES", "MKS_FIRMWARES", "MKS_HEARTBEAT", "MKS_HOMING_STATUS", "MKS_IAP",
           "MKS_IN1_PORT_MODE", "MKS_MODBUS_NOLIMIT_HOME",
           "MKS_PID", "MKS_POSITION_ERROR_PROTECTION",
           "MKS_POSITION_THRESHOLD", "MKS_PULSE_DIVIDER", "MKS_READ_PARAMETER", "MKS_SINGLE_LAP_HOME", "MKS_SYNC", "MKS_TIMED_RETURNS", "MKS_TIMED_SPEED", "MKS_USER_ID", "MKS_VERSION", "MKS_WRITE_IO",
           "QUIRKS",
           "ZLAC_SYNC_FLAG_AS_EXAMPLES", "FirmwareProfile", "Quirk", "firmware_profile"]


@dataclass(frozen=True)
class Quirk:
    """One deviation of a firmware from its manual."""

    name: str
    family: str  #: device family (registry name)
    errata: str  #: the ERRATA id it corresponds to
    behaviour: str  #: what the firmware does (the twin reproduces this)
    workaround: str  #: what the driver does about it


@dataclass(frozen=True)
class FirmwareProfile:
    """The quirks of one firmware version of one device family."""

    family: str
    firmware: str  #: the config's ``firmware`` value
    quirks: frozenset[str]
    description: str
    features: frozenset[str] = frozenset()  #: commands this firmware adds over its family's oldest profile
    version: tuple[int, ...] = ()  #: the version the drive reports for it (MKS 0x40: major, minor, patch)


ZLAC_SYNC_FLAG_AS_EXAMPLES = "zlac-sync-flag-as-examples"
#: eRob on CANopen: 0x6060 taken while OPERATION ENABLED (E7 of joints.devices.erob.canopen; not in any erratum)
EROB_CANOPEN_MODE_CHANGE_WHILE_ENABLED = "erob-canopen-mode-change-while-enabled"
MKS_FAILURE_REPLIES = "mks-failure-replies"
MKS_ALL_PARAMETERS = "mks-all-parameters"
MKS_VERSION = "mks-version"
MKS_HEARTBEAT = "mks-heartbeat"
MKS_TIMED_RETURNS = "mks-timed-returns"
MKS_WRITE_IO = "mks-write-io"
MKS_POSITION_ERROR_PROTECTION = "mks-position-error-protection"
MKS_POSITION_THRESHOLD = "mks-position-threshold"
MKS_SYNC = "mks-sync"
MKS_TIMED_SPEED = "mks-timed-speed"
MKS_IAP = "mks-iap"
MKS_PID = "mks-pid"
MKS_CURRENT_UNSAVED = "mks-current-unsaved"
MKS_HOMING_STATUS = "mks-homing-status"
MKS_COORDINATE_HOMING = "mks-coordinate-homing"
MKS_READ_PARAMETER = "mks-read-parameter"
MKS_USER_ID = "mks-user-id"
MKS_MODBUS_NOLIMIT_HOME = "mks-modbus-nolimit-home"
MKS_PULSE_DIVIDER = "mks-pulse-divider"
MKS_IN1_PORT_MODE = "mks-in1-port-mode"
MKS_SINGLE_LAP_HOME = "mks-single-lap-home"
#: the MKS firmware profiles, oldest first (the last is the default)
MKS_FIRMWARES = ("v1.0.5", "v1.0.6", "v1.0.9")
_MKS_FEATURES = {
    "v1.0.5": frozenset(),
    "v1.0.6": frozenset({MKS_FAILURE_REPLIES, MKS_ALL_PARAMETERS, MKS_WRITE_IO, MKS_POSITION_ERROR_PROTECTION,
                         MKS_MODBUS_NOLIMIT_HOME}),
    "v1.0.9": frozenset({MKS_FAILURE_REPLIES, MKS_ALL_PARAMETERS, MKS_VERSION, MKS_HEARTBEAT, MKS_TIMED_RETURNS,
                         MKS_WRITE_IO, MKS_POSITION_ERROR_PROTECTION, MKS_POSITION_THRESHOLD,
                         MKS_SYNC, MKS_TIMED_SPEED, MKS_IAP, MKS_PID, MKS_CURRENT_UNSAVED,
                         MKS_HOMING_STATUS, MKS_COORDINATE_HOMING, MKS_READ_PARAMETER,
                         MKS_USER_ID, MKS_MODBUS_NOLIMIT_HOME, MKS_PULSE_DIVIDER, MKS_IN1_PORT_MODE,
                         MKS_SINGLE_LAP_HOME}),
}
_MKS_TEXT = {
    "v1.0.5": "manual V1.0.5 (May 2024): no heartbeat, no version command; Modbus write failures undocumented",
    "v1.0.6": "manual V1.0.6 (Sep 2024): Modbus write failures answered by FC06 data 0xFFFF / FC16 quantity 0; "
              "0x46/0x47/0x48 write/read all parameters",
    "v1.0.9": "manual V1.0.9 (Nov 2025): + 0x40 version, 0x98 heartbeat protection (the communication watchdog), "
              "0x01 timed returns",
}

QUIRKS: Mapping[str, Quirk] = MappingProxyType({q.name: q for q in (
    Quirk(ZLAC_SYNC_FLAG_AS_EXAMPLES, "zlac8015d", "DOC-ZLAC-1",
          "0x200F: 0 = asynchronous, 1 = synchronous (the section 3.2 examples; the register table says the opposite)",
          "write 1 for synchronous and 0 for asynchronous control"),
    Quirk(EROB_CANOPEN_MODE_CHANGE_WHILE_ENABLED, "erob", "E7",
          "0x6060 written while OPERATION ENABLED is taken (ZeroErr's Linux node writes it right after 0x0F) "
          "instead of the default refusal with SDO abort 0x08000022",
          "none needed: the driver's mode change goes through NMT reset communication, which disables first"),
)})

FIRMWARES: Mapping[tuple[str, str], FirmwareProfile] = MappingProxyType({(p.family, p.firmware): p for p in (
    FirmwareProfile("zlac8015d", "examples", frozenset({ZLAC_SYNC_FLAG_AS_EXAMPLES}),
                    "the firmware of the manual's section 3.2 examples and of the community drivers"),
    FirmwareProfile("zlac8015d", "register-table", frozenset(),
                    "a firmware that follows the chapter-4 register table for 0x200F (choose it if wheels "
                    "started with Start(Synchronous) stay still with the default)"),
    FirmwareProfile("erob", "mode-change-while-enabled", frozenset({EROB_CANOPEN_MODE_CHANGE_WHILE_ENABLED}),
                    "an eRob that takes a CANopen mode change (0x6060) while enabled; choose it if a real drive "
                    "does (the default profile refuses it, as the eRunner manual's section 5.1 asks)"),
    *(FirmwareProfile("mks", fw, frozenset(), _MKS_TEXT[fw], _MKS_FEATURES[fw],
                      tuple(int(x) for x in fw[1:].split("."))) for fw in MKS_FIRMWARES),
)})

#: family -> the firmware a joint has when its config names none
DEFAULT_FIRMWARE: Mapping[str, str] = MappingProxyType({"zlac8015d": "examples", "mks": MKS_FIRMWARES[-1]})


def firmware_profile(family: str, firmware: str | None = None) -> FirmwareProfile:
    """The firmware profile ``firmware`` of ``family`` (None: the family's default; a family with no
    known quirks has an empty default profile). Raises :class:`ConfigError` listing the known ones."""
    known = sorted(f for fam, f in FIRMWARES if fam == family)
    name = firmware if firmware is not None else DEFAULT_FIRMWARE.get(family)
    if name is None:
        return FirmwareProfile(family, "default", frozenset(), "no known quirks")
    found = FIRMWARES.get((family, name))
    if found is None:
        raise ConfigError(f"no firmware profile {name!r} for {family}", key="firmware",
                          allowed=known or ("(none: this family has no known quirks)",))
    return found
