"""Find the nodes of a CANopen bus and what they say they are (``joints scan``), for any CiA 301 node.

Rule: read-only. Nothing is written and no NMT command is sent (a reset would make every node
announce itself with a boot-up, and also stop drives that run): a scan listens, then asks.

1. Listen for ``listen`` seconds: every heartbeat, boot-up or EMCY names a node (and its NMT
   state). Nodes whose heartbeat producer is off stay silent here.
2. SDO probe of each address: an upload of 0x1000 (device type; every CiA 301 node has it). An
   answer - a value or an abort - is a node. A node heard in step 1 that does not answer is
   reported too (a STOPPED node answers no SDO).
3. Identity of each node found, where readable: 0x1018 sub-indexes 1..4 (vendor id, product code,
   revision, serial number) as many as 0x1018:00 says, and the strings 0x1008/0x1009/0x100A
   (device name, hardware and software version). A CiA 402 drive (device type profile 402) also
   gives 0x6502 (supported modes), 0x603F (error code) and its CiA 402 state (0x6041). An object
   the node refuses (SDO abort) is left out, not guessed.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Any

from joints.codecs import canopen as co
from joints.devices import cia402
from joints.errors import DeviceRejected, JointsError, PeerProtocolError

__all__ = ["IDENTITY", "scan"]

#: 0x1018 sub-index -> record key
IDENTITY = {1: "vendor_id", 2: "product_code", 3: "revision_number", 4: "serial_number"}
_STRINGS = {0x1008: "device_name", 0x1009: "hardware_version", 0x100A: "software_version"}


def _u(data: bytes) -> int:
    return int.from_bytes(data, "little")


def scan(link: Any, nodes: Iterable[int], *, listen: float = 0.0) -> Iterator[dict[str, object]]:
    """One record per node found, in address order (see the module docstring); ``link``: a CanopenLink."""
    heard: dict[int, str] = {}

    def note(msg: Any) -> None:
        if isinstance(msg, co.BootUp):
            heard[msg.node] = f"{co.AFTER_BOOT_UP.name} (boot-up)"
        elif isinstance(msg, co.Heartbeat):
            heard[msg.node] = msg.state.name
        else:
            heard.setdefault(msg.node, "unknown (EMCY)")

    sub = link.subscribe(lambda m: isinstance(m, (co.Heartbeat, co.BootUp, co.Emcy)), note)
    try:
        link.poll(max(listen, 0.0))
        for node in nodes:
            record: dict[str, object] = {"address": node}
            device_type: int | None = None
            try:
                device_type = _u(link.sdo_upload(node, 0x1000, 0))
            except DeviceRejected as exc:  # it answered: a node, with an odd dictionary
                record["device_type"] = f"unreadable: {exc}"
            except JointsError:  # no SDO answer (no node; or a node that is STOPPED)
                if node not in heard:
                    continue
                record["nmt"] = heard[node]
                record["sdo"] = "no answer (NMT STOPPED?)"
                yield record
                continue
            else:
                record["device_type"] = f"0x{device_type:08X}"
                record["profile"] = device_type & 0xFFFF
            if node in heard:
                record["nmt"] = heard[node]
            try:
                _identity(link, node, record, device_type)
            except JointsError as exc:  # the node went away in the middle
                record["identity"] = f"failed: {exc}"
            yield record
    finally:
        sub.cancel()


def _identity(link: Any, node: int, record: dict[str, object], device_type: int | None) -> None:
    def read(index: int, sub: int, put: Callable[[bytes], object], key: str) -> None:
        try:
            record[key] = put(link.sdo_upload(node, index, sub))
        except (DeviceRejected, PeerProtocolError):
            pass  # not in this node's dictionary

    try:
        count = min(_u(link.sdo_upload(node, 0x1018, 0)), 4)
    except (DeviceRejected, PeerProtocolError):
        count = 0
    for sub in range(1, count + 1):
        read(0x1018, sub, lambda d: f"0x{_u(d):08X}", IDENTITY[sub])
    for index, key in _STRINGS.items():
        read(index, 0, lambda d: d.rstrip(b"\0").decode("ascii", "replace"), key)
    if device_type is not None and device_type & 0xFFFF == 402:
        read(0x6502, 0, lambda d: sorted(m.name.lower() for m in cia402.modes_from_bits(_u(d))), "modes")
        read(0x603F, 0, lambda d: f"0x{_u(d):04X}", "error_code")
        read(0x6041, 0, lambda d: _state(_u(d)), "state")


def _state(statusword: int) -> str:
    try:
        return cia402.state_of(statusword).value
    except JointsError:
        return f"statusword 0x{statusword:04X}"
