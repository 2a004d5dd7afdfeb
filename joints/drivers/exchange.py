"""What one recorded exchange (a host request and the frames that came back) carried, by name.

Rule: pure decoding of frames that already crossed a bus, for replay's diff and plots; no I/O.
One function per protocol, named by the registry's protocol entry (``BusProtocol.values``), so
nothing outside the registry asks which protocol a bus speaks. ``tables`` maps a bus address to
its joint and the joint's parameter map on this protocol; frames have ``data``, ``can_id`` and
``extended``. A function returns ``None`` when it cannot name the exchange (the caller then
compares bytes).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import fields
from typing import Any

from joints.errors import JointsError

Tables = Mapping[int, tuple[str, Any]]


def modbus_values(tables: Tables, request: Any, replies: Sequence[Any]) -> dict[str, Any] | None:
    """Modbus RTU: a register read by register name (the family's table), else by address; any
    other reply by its fields."""
    from joints.codecs import modbus as mb
    from joints.devices.registers import RegisterTable

    if request.can_id is not None:
        return None
    dev = mb.ModbusRtuCodec(mb.Role.DEVICE)
    dev.feed(request.data)
    dev.flush()
    host = mb.ModbusRtuCodec(mb.Role.HOST)
    host.feed(b"".join(f.data for f in replies))
    host.flush()
    try:
        req = dev.next_message()
        rep = host.next_message()
    except JointsError:
        return None
    out: dict[str, Any] = {}
    if isinstance(req, (mb.ReadHoldingRegisters, mb.ReadInputRegisters)) and isinstance(rep, mb.ReadRegistersReply):
        joint, table = tables.get(req.slave, (str(req.slave), None))
        prefix = f"{joint}."
        if isinstance(table, RegisterTable):
            for name, value in table.decode_block(req.address, rep.values).items():
                out[prefix + name] = value
            return out
        for i, v in enumerate(rep.values):
            out[f"{prefix}0x{req.address + i:04X}"] = v
        return out
    if rep is None:
        return None
    for fld in fields(rep):
        out[f"{rep.slave}.{type(rep).__name__}.{fld.name}"] = getattr(rep, fld.name)
    return out


def erob_can_values(tables: Tables, request: Any, replies: Sequence[Any]) -> dict[str, Any] | None:
    """eRob CAN custom protocol: a read and its value, as {joint.parameter: value}."""
    import can

    from joints.codecs import erob_can as ec
    from joints.devices.erob.can import CanMap

    if request.can_id is None or len(replies) != 1 or replies[0].can_id is None:
        return None

    def frame(f: Any) -> can.Message:
        return can.Message(arbitration_id=f.can_id or 0, is_extended_id=f.extended, data=f.data)

    try:
        req = ec.decode(frame(request), ec.Role.DEVICE)
        rep = ec.decode(frame(replies[0]), ec.Role.HOST)
        if not (isinstance(req, ec.Read) and isinstance(rep, ec.ValueReply)):
            return None
        joint, table = tables.get(req.node, (str(req.node), None))
        if not isinstance(table, CanMap):
            return None
        name = table.at(req.index, req.subindex)
        value = table.from_wire(name, rep.value)
    except (JointsError, KeyError, ValueError):
        return None
    return {f"{joint}.{name}": value}
