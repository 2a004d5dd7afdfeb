"""The ``canopen`` package (2.4.x) as an independent peer of our codec.

Its SDO client talks to our :class:`SdoServer`, our :class:`SdoClient` talks to its SDO server
(``LocalNode``), both expedited and segmented, with aborts; its PDO maps, built from an object
dictionary made of our eRob map, pack and unpack the same bytes as ours and configure a PDO with
the same SDO writes. Frames go by hand through a :class:`canopen.Network` whose ``send_message``
answers at once, so its clients find their reply queued before they wait: no bus, no sleeps.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable
from typing import Any

import can
import pytest

from joints.codecs import canopen as co
from joints.devices.cia402 import Mode
from joints.devices.erob.canopen import ERUNNER_RPDO1, OBJECT_NAMES, objects, power_on_pdo
from joints.errors import DeviceRejected

canopen: Any = pytest.importorskip("canopen")

NODE = 2


class LoopNetwork(canopen.Network):  # type: ignore[misc]
    """A network without a bus: each sent frame is handed to ``handler``; its replies are delivered at once."""

    def __init__(self, handler: Callable[[can.Message], list[can.Message]]) -> None:
        super().__init__()
        self.handler = handler
        self.sent: list[can.Message] = []

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        msg = can.Message(arbitration_id=can_id, data=bytes(data), is_extended_id=False, is_remote_frame=remote)
        self.sent.append(msg)
        for reply in self.handler(msg):
            self.notify(reply.arbitration_id, bytearray(reply.data), 0.0)


def erob_object_dictionary() -> Any:
    """Our eRob map as a ``canopen.ObjectDictionary`` (defaults resolved for node 2)."""
    od = canopen.ObjectDictionary()
    by_index: dict[int, list[Any]] = defaultdict(list)
    for _name, obj in objects():
        var = canopen.objectdictionary.ODVariable(obj.name, obj.index, obj.subindex)
        var.data_type = int(obj.datatype)
        var.access_type = obj.access.value
        var.default = obj.default(NODE)
        var.pdo_mappable = obj.pdo_mappable
        by_index[obj.index].append(var)
    for index, variables in by_index.items():
        if index in OBJECT_NAMES:
            record = canopen.objectdictionary.ODRecord(OBJECT_NAMES[index], index)
            for var in variables:
                record.add_member(var)
            od.add_object(record)
        else:
            (var,) = variables
            od.add_object(var)
    return od


class Dictionary:
    def __init__(self) -> None:
        self.values: dict[tuple[int, int], bytes] = {(0x1008, 0): b"eRob70H100I-BM-18EN", (0x6061, 0): b"\x08"}
        self.writes: list[tuple[int, int, bytes]] = []

    def read(self, index: int, subindex: int) -> bytes:
        if (index, subindex) not in self.values:
            raise DeviceRejected("no object", code=co.SdoAbortCode.OBJECT_DOES_NOT_EXIST)
        return self.values[(index, subindex)]

    def write(self, index: int, subindex: int, data: bytes) -> None:
        self.values[(index, subindex)] = data
        self.writes.append((index, subindex, data))


def their_client_our_server() -> tuple[Any, Dictionary, LoopNetwork]:
    od = Dictionary()
    server = co.SdoServer(NODE, od.read, od.write)

    def handler(msg: can.Message) -> list[can.Message]:
        reply = server.feed(msg)
        return [] if reply is None else [reply]

    network = LoopNetwork(handler)
    node = canopen.RemoteNode(NODE, canopen.ObjectDictionary())
    network.add_node(node)
    return node, od, network


# ---------------------------------------------------------------------------- their SDO client


def test_their_expedited_requests_are_our_frames() -> None:
    node, od, network = their_client_our_server()
    node.sdo.download(0x6081, 0, bytes.fromhex("BE 15 00 00"))
    assert node.sdo.upload(0x6061, 0) == b"\x08"
    ours = co.SdoClient(NODE)
    assert bytes(network.sent[0].data) == bytes(ours.download(0x6081, 0, bytes.fromhex("BE 15 00 00")).data)
    ours.abort()
    assert bytes(network.sent[1].data) == bytes(ours.upload(0x6061, 0).data)
    assert od.writes == [(0x6081, 0, bytes.fromhex("BE 15 00 00"))]


@pytest.mark.parametrize("value", [b"x", b"0123", b"01234", b"0123456", b"01234567", bytes(range(50))])
def test_their_client_segmented_and_expedited_against_our_server(value: bytes) -> None:
    node, od, _network = their_client_our_server()
    od.values[(0x2000, 1)] = value
    assert node.sdo.upload(0x2000, 1) == value
    node.sdo.download(0x2001, 0, value, force_segment=True)
    assert od.writes[-1] == (0x2001, 0, value)
    node.sdo.download(0x2002, 0, value)
    assert od.writes[-1] == (0x2002, 0, value)


def test_their_client_sees_our_aborts() -> None:
    node, _od, _network = their_client_our_server()
    with pytest.raises(canopen.SdoAbortedError) as info:
        node.sdo.upload(0x6099, 0)
    assert info.value.code == 0x06020000


# ---------------------------------------------------------------------------- their SDO server


def our_client_their_server() -> tuple[co.SdoClient, Callable[[can.Message], can.Message], Any]:
    od = canopen.ObjectDictionary()
    for index, dtype, default in ((0x6061, canopen.objectdictionary.INTEGER8, 8),
                                  (0x6081, canopen.objectdictionary.UNSIGNED32, 0),
                                  (0x1008, canopen.objectdictionary.VISIBLE_STRING, "eRob70H100I-BM-18EN"),
                                  (0x2001, canopen.objectdictionary.OCTET_STRING, b"")):
        var = canopen.objectdictionary.ODVariable(f"o{index:04X}", index)
        var.data_type, var.default, var.access_type = dtype, default, "rw"
        od.add_object(var)
    outbox: list[can.Message] = []

    def handler(msg: can.Message) -> list[can.Message]:
        outbox.append(msg)
        return []

    network = LoopNetwork(handler)
    local = canopen.LocalNode(NODE, od)
    network.add_node(local)

    def exchange(request: can.Message) -> can.Message:
        outbox.clear()
        local.sdo.on_request(request.arbitration_id, bytearray(request.data), 0.0)
        (reply,) = outbox
        return reply

    return co.SdoClient(NODE), exchange, local


def transfer(client: co.SdoClient, exchange: Callable[[can.Message], can.Message], first: can.Message) -> co.SdoStep:
    request = first
    while True:
        step = client.feed(exchange(request))
        if not isinstance(step, co.SdoSend):
            return step
        request = step.frame


def test_our_client_against_their_server() -> None:
    client, exchange, local = our_client_their_server()
    assert transfer(client, exchange, client.upload(0x6061, 0)) == co.SdoDone(b"\x08")
    assert transfer(client, exchange, client.upload(0x1008, 0)) == co.SdoDone(b"eRob70H100I-BM-18EN")
    assert transfer(client, exchange, client.download(0x6081, 0, (5566).to_bytes(4, "little"))) == co.SdoDone()
    assert local.sdo[0x6081].raw == 5566
    blob = bytes(range(33))
    assert transfer(client, exchange, client.download(0x2001, 0, blob)) == co.SdoDone()
    assert local.sdo[0x2001].raw == blob
    assert transfer(client, exchange, client.download(0x2001, 0, b"ab", segmented=True)) == co.SdoDone()
    assert local.sdo[0x2001].raw == b"ab"


def test_our_client_sees_their_aborts() -> None:
    client, exchange, _local = our_client_their_server()
    step = transfer(client, exchange, client.upload(0x6099, 0))
    assert isinstance(step, co.SdoFailed) and isinstance(step.error, DeviceRejected)
    assert step.error.code == 0x06020000
    step = transfer(client, exchange, client.download(0x6081, 0, b"\x01"))  # wrong length for UNSIGNED32
    assert isinstance(step, co.SdoFailed) and isinstance(step.error, DeviceRejected)
    assert step.error.code == co.SdoAbortCode.LENGTH_MISMATCH


# ---------------------------------------------------------------------------- PDO


def remote_erob() -> tuple[Any, Dictionary]:
    od = Dictionary()
    server = co.SdoServer(NODE, od.read, od.write)

    def handler(msg: can.Message) -> list[can.Message]:
        reply = server.feed(msg) if msg.arbitration_id == 0x600 + NODE else None
        return [] if reply is None else [reply]

    network = LoopNetwork(handler)
    node = canopen.RemoteNode(NODE, erob_object_dictionary())
    network.add_node(node)
    node.rpdo.read(from_od=True)
    node.tpdo.read(from_od=True)
    return node, od


@pytest.mark.parametrize("kind", ["RPDO", "TPDO"])
@pytest.mark.parametrize("number", [1, 2, 3, 4])
def test_their_view_of_the_power_on_mapping_is_ours(kind: str, number: int) -> None:
    node, _od = remote_erob()
    theirs = (node.rpdo if kind == "RPDO" else node.tpdo)[number]
    ours = power_on_pdo(kind, number)
    assert theirs.enabled == (number == 1)  # E4: only RPDO1/TPDO1 valid at power-on
    assert theirs.cob_id == ours.cob_id(NODE)
    assert theirs.trans_type == ours.transmission_type
    assert [(v.index, v.subindex, v.length) for v in theirs] == [e[:3] for e in ours.entries]


def test_their_pdo_packing_is_ours() -> None:
    node, _od = remote_erob()
    rpdo = node.rpdo[2]  # controlword + target position (ZeroErr's EDS)
    for cw, target in ((0x1F, 0), (0x2F, 0x0021F368), (0x06, -123456)):
        rpdo[0x6040].raw = cw
        rpdo[0x607A].raw = target
        entries = power_on_pdo("RPDO", 2).entries
        assert bytes(rpdo.data) == co.pack_pdo(entries, [cw, target])
    tpdo = node.tpdo[3]  # statusword + velocity actual value
    data = co.pack_pdo(power_on_pdo("TPDO", 3).entries, [0x1637, -5566])
    tpdo.on_message(tpdo.cob_id, bytearray(data), 0.0)
    assert (tpdo[0x6041].raw, tpdo[0x606C].raw) == (0x1637, -5566)


def test_their_pdo_configuration_writes_are_ours() -> None:
    node, od = remote_erob()
    rpdo = node.rpdo[1]
    rpdo.clear()
    for index, subindex, _bits, _signed in ERUNNER_RPDO1[Mode.PP].entries:
        rpdo.add_variable(index, subindex)
    rpdo.trans_type = 255
    rpdo.event_timer = 0
    rpdo.enabled = True
    rpdo.save()
    theirs = [(i, s, int.from_bytes(d, "little")) for i, s, d in od.writes]
    # ZeroErr's EDS has an RPDO inhibit time (0x1400:03): canopen writes it
    ours = co.pdo_configuration_writes(co.Kind.RPDO1, co.PdoComm(0x200 + NODE, 255, 0, 0),
                                       ERUNNER_RPDO1[Mode.PP].entries)
    assert theirs == [(i, s, v) for i, s, v, _size in ours]
    assert [len(d) for _i, _s, d in od.writes] == [size for *_x, size in ours]

