"""The eRob CANopen twin against ZeroErr's EDS (issue 31), with the ``canopen`` package as the peer.

ZeroErr's EDS is in ``tests/data/zeroerr_eds.json`` as an extract (made by ``tests/data/erob_eds.py``:
the file's licence is not stated, its facts are kept). The peer reads it back as an EDS
(:func:`joints.devices.canopen.format_eds`), the way a user hands ``ZeroErr Driver_V1.5.eds`` to
``canopen``. Frames go by hand to the twin's bus (:meth:`ErobCanopenBus.on_frame`) and the world is
stepped in lockstep: no wall clock.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can
import pytest
from edskit import vendor, vendor_eds

import simkit
from joints.devices.erob import od as erob_od
from joints.devices.erob.eds import eds_text
from joints.devices.erob.profiles import profile
from joints.devices.erob.registers import EROB_MODBUS
from joints.devices.quirks import firmware_profile
from joints.sim.erob import COUNTS_PER_REV, ErobFirmware, power_on_defaults
from joints.sim.erob_canopen import CanopenFront, ErobCanopenBus
from joints.sim.modbus_front import ModbusFront

canopen: Any = pytest.importorskip("canopen")

NODE = 2
DEG = COUNTS_PER_REV / 360.0


class LoopNetwork(canopen.Network):  # type: ignore[misc]
    """A network without a bus: each frame goes to ``handler``; its answers are delivered at once."""

    def __init__(self, handler: Callable[[can.Message], Any]) -> None:
        super().__init__()
        self.handler = handler

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        msg = can.Message(arbitration_id=can_id, data=bytes(data), is_extended_id=False, is_remote_frame=remote)
        for reply in self.handler(msg):
            self.notify(reply.arbitration_id, bytearray(reply.data), 0.0)


def twin(eds: Path) -> tuple[Any, Any, Any]:
    """(world, front, canopen RemoteNode on ``eds``) with the node booted."""
    world = simkit.world("erob_stand.xml", [simkit.drive("joint1", NODE, profile("eRob80H100"), bus="can",
                                                         protocol="canopen")])
    bus = world.buses["can"]
    world.step(2)  # the boot-up
    network = LoopNetwork(bus.on_frame)
    node = canopen.RemoteNode(NODE, canopen.import_od(str(eds), NODE))
    network.add_node(node)
    return world, bus.front(NODE), node


# --- the dictionary --------------------------------------------------------------------------


def test_the_package_reads_the_same_extract_the_tests_keep() -> None:
    """The twin's data file is the script's output, not edited by hand."""
    ours = json.loads(erob_od.resources.files("joints.devices.erob").joinpath(erob_od.DATA_FILE).read_text("utf-8"))
    assert ours == vendor()
    assert vendor()["source"]["sha256"] == "cf9b38ce595e8f4dd794a0b9ddee3903ebd9277cc2b75755cfba4cd9bbaa9b4d"


def test_export_matches_zeroerr_eds_except_the_listed_deviations(tmp_path: Path) -> None:
    """Every object and sub-index of ZeroErr's EDS is in the twin's export with the same data type
    (one listed exception); access, PDO flag and default differ exactly where DEVIATIONS says."""
    path = tmp_path / "twin.eds"
    path.write_text(eds_text(3, power_on_defaults(profile("eRob80H100"), 3)), encoding="utf-8")
    theirs = canopen.import_od(str(path), 3)
    exported = {}
    for obj in theirs.values():
        for var in ([obj] if isinstance(obj, canopen.objectdictionary.ODVariable) else obj.values()):
            if var.index >= 0x1000:  # not the dummy data types of [DummyUsage]
                exported[(var.index, var.subindex)] = var
    listed = {(d.index, d.subindex, d.field) for d in erob_od.DEVIATIONS}
    expected = {}
    for o in vendor()["objects"]:
        for sub, _name, dt, access, pdo, default, rel, _lo, _hi in o["variables"]:
            expected[(o["index"], sub)] = (dt, access, bool(pdo), default, bool(rel))
    assert set(exported) == set(expected)  # presence, both ways
    differ = set()
    kinds = {o["index"]: o["object_type"] for o in vendor()["objects"]}
    for index, kind in kinds.items():
        record = isinstance(theirs[index], canopen.objectdictionary.ODRecord)
        array = isinstance(theirs[index], canopen.objectdictionary.ODArray)
        if (kind == 8) != array or (kind == 9) != record:
            differ.add((index, 0, "object_type"))
    for key, (dt, access, pdo, default, rel) in expected.items():
        var = exported[key]
        got_default = var.default - (3 if rel and var.default is not None else 0) if default is not None else None
        for field, a, b in (("datatype", dt, var.data_type), ("access", access, var.access_type),
                            ("pdo_mappable", pdo, var.pdo_mappable), ("default", default, got_default)):
            if a != b:
                differ.add((*key, field))
    assert differ == listed
    assert {f for *_k, f in listed} <= {"datatype", "access", "default", "object_type"}
    assert "0x6502:00 default" in path.read_text() and "5.7" in path.read_text()  # the list is in the EDS comments


def test_objects_the_issue_names(tmp_path: Path) -> None:
    _world, _front, node = twin(vendor_eds(tmp_path / "zeroerr.eds"))
    sdo = node.sdo
    assert sdo[0x1000].raw == 0x00420192 and sdo[0x1018][1].raw == 0x5A65726F and sdo[0x1018][0].raw == 3
    assert sdo[0x1006].raw == 0  # the EDS's power-on value
    assert sdo[0x1400][3].raw == 0  # RPDO inhibit time exists (0x06090011 before)
    assert sdo[0x1601][2].raw == 0x607A0020 and sdo[0x1A01][2].raw == 0x60640020 and sdo[0x1603][0].raw == 0
    for index, sub in ((0x1800, 6), (0x1018, 4)):
        with pytest.raises(canopen.SdoAbortedError) as info:
            sdo.upload(index, sub)
        assert info.value.code == 0x06090011
    for index in (0x6073, 0x605A):
        with pytest.raises(canopen.SdoAbortedError) as info:
            sdo.upload(index, 0)
        assert info.value.code == 0x06020000
    # homing objects exist as stored values (0x6502 has no homing bit)
    sdo[0x6098].raw = 35
    sdo[0x6099][1].raw = 1234
    sdo[0x609A].raw = 5678
    assert (sdo[0x6098].raw, sdo[0x6099][1].raw, sdo[0x609A].raw) == (35, 1234, 5678)
    assert not sdo[0x6502].raw & (1 << 5)
    with pytest.raises(canopen.SdoAbortedError) as info:
        sdo[0x606B].raw = 5  # listed deviation: ro
    assert info.value.code == 0x06010002


def test_temperature_over_canopen_is_the_modbus_temperature(tmp_path: Path) -> None:
    """0x22A2 (U16, degC: an assumption) = Modbus 0x0078 part_of_power_temperature (int16 degC)."""
    _world, front, node = twin(vendor_eds(tmp_path / "zeroerr.eds"))
    modbus = ModbusFront(front.firmware, EROB_MODBUS, node_id="modbus_address")  # the same drive's Modbus side
    for celsius in (24.6, 61.2, 87.0):
        front.firmware.temperature = celsius
        (register,) = modbus.read(0x0078, 1)
        assert register == round(celsius)
        assert node.sdo[0x22A2].raw == register


# --- CiA 301 ---------------------------------------------------------------------------------


def test_load_configuration_with_zeroerr_eds_succeeds(tmp_path: Path) -> None:
    """canopen's RemoteNode.load_configuration() writes the EDS's PDO configuration (0x1400:03 inhibit
    time included) and every writable object with a value; the twin takes all of it."""
    _world, front, node = twin(vendor_eds(tmp_path / "zeroerr.eds"))
    node.load_configuration()
    assert node.sdo[0x1400][3].raw == 0 and node.sdo[0x1601][2].raw == 0x607A0020
    assert front.pdos()[("rpdo", 2)].entries[1][:2] == (0x607A, 0)


def test_sync_producer_is_refused_not_ignored(tmp_path: Path) -> None:
    """0x1005 = 0x40000080 (bit 30: produce SYNC): no evidence an eRob can, so the write is refused."""
    _world, _front, node = twin(vendor_eds(tmp_path / "zeroerr.eds"))
    node.sdo[0x1006].raw = 20000
    with pytest.raises(canopen.SdoAbortedError) as info:
        node.sdo[0x1005].raw = 0x40000080
    assert info.value.code == 0x06090030
    assert node.sdo[0x1005].raw == 0x80
    node.sdo[0x1005].raw = 0x80  # a consumer COB-ID is taken


# --- CiA 402 CSP -----------------------------------------------------------------------------


def spline(t: float) -> float:
    """45 -> 135 -> 45 degrees, cubic legs of 2.5 s with zero end velocities."""
    leg, u = divmod(t, 2.5)
    u = min(u / 2.5, 1.0) if leg < 2 else 1.0
    s = 3 * u * u - 2 * u ** 3
    return 45.0 + 90.0 * (s if leg == 0 else 1.0 - s)


def test_csp_setpoints_every_10ms_with_1006_at_1ms_follow_without_fault(tmp_path: Path) -> None:
    """The community script's stream: one set-point (RPDO2, power-on mapping 0x6040 + 0x607A) and one
    SYNC every 10 ms while 0x1006 says 1000 us. The reference moves over the measured SYNC interval
    and stops at the newest set-point: no fault, within 1 deg of the newest set-point throughout,
    within 0.1 deg of 45 deg at the end. Angles are measured from where the joint starts (= 45 deg)."""
    world, front, node = twin(vendor_eds(tmp_path / "zeroerr.eds"))
    sdo = node.sdo
    sdo[0x1006].raw = 1000
    sdo[0x6060].raw = 8
    sdo[0x1401][1].raw = 0x300 + NODE  # RPDO2 valid (type 255: applied at once)
    network = node.network
    network.send_message(0x000, bytes([0x01, NODE]))  # NMT start
    fw = front.firmware
    zero = fw.read("actual_position") - round(45 * DEG)
    steps = round(0.010 / world.timestep)

    def cycle(cw: int, degrees: float) -> float:
        """One set-point and one SYNC, 10 ms of world; the reference speed halfway [deg/s]."""
        target = zero + round(degrees * DEG)
        network.send_message(0x300 + NODE, cw.to_bytes(2, "little") + target.to_bytes(4, "little", signed=True))
        network.send_message(0x080, b"")
        world.step(steps // 2)
        speed = fw.v_ref / DEG
        world.step(steps - steps // 2)
        return speed

    for cw in (0x06, 0x07, 0x0F):
        cycle(cw, 45.0)
    for _ in range(60):  # the brake releases (0.5 s)
        cycle(0x0F, 45.0)
    assert sdo[0x6041].raw & 0x6F == 0x27  # OPERATION ENABLED
    worst = 0.0
    for k in range(1, 501):  # 5 s
        newest = spline(k * 0.010)
        speed = cycle(0x0F, newest)
        if k == 125:  # mid first leg: 54 deg/s, interpolated over the SYNC interval (not 0x1006's 1 ms)
            assert speed == pytest.approx(1.5 * 90 / 2.5, rel=0.05)
        assert not fw.fault and front.state.name == "OPERATION_ENABLED", (k, fw.fault)
        worst = max(worst, abs((fw.read("actual_position") - zero) / DEG - newest))
    for _ in range(50):
        cycle(0x0F, 45.0)
    end = (fw.read("actual_position") - zero) / DEG
    print(f"worst {worst:.3f} deg, end {end:.4f} deg, SYNC interval {front.sync_interval}")
    assert worst < 1.0
    assert abs(end - 45.0) < 0.1
    assert front.sync_interval == pytest.approx(0.010, abs=world.timestep)
    assert math.isfinite(end)


def test_csp_reference_never_passes_the_newest_setpoint_when_setpoints_stop(tmp_path: Path) -> None:
    """Set-points at 10 deg/s, then SYNCs only: the reference stops at the last set-point, no fault."""
    world, front, node = twin(vendor_eds(tmp_path / "zeroerr.eds"))
    sdo, network, fw = node.sdo, node.network, front.firmware
    sdo[0x6060].raw = 8
    sdo[0x1401][1].raw = 0x300 + NODE
    network.send_message(0x000, bytes([0x01, NODE]))
    start = fw.read("actual_position")
    steps = round(0.010 / world.timestep)
    target = start
    for k in range(160):
        if k >= 60:  # brake released: move at 0.1 deg per 10 ms
            target = start + round((k - 60) * 0.1 * DEG)
        cw = (0x06, 0x07)[k] if k < 2 else 0x0F
        network.send_message(0x300 + NODE, cw.to_bytes(2, "little") + target.to_bytes(4, "little", signed=True))
        network.send_message(0x080, b"")
        world.step(steps)
    for _ in range(20):  # the host stops sending set-points; SYNC goes on
        network.send_message(0x080, b"")
        for _ in range(steps):
            world.step(1)
            assert fw.p_ref + fw.offset <= target + 1e-6
    assert not fw.fault
    assert abs(fw.read("actual_position") - target) < 0.05 * DEG


# --- E7: a mode change while enabled -----------------------------------------------------------


@pytest.mark.parametrize("firmware", [None, "mode-change-while-enabled"])
def test_mode_change_while_enabled_follows_the_firmware_profile(firmware: str | None, tmp_path: Path) -> None:
    """Default: 0x6060 in OPERATION ENABLED is refused with 0x08000022 (E7, no evidence either way); the
    firmware profile ``mode-change-while-enabled`` takes it (what ZeroErr's Linux node expects)."""
    quirks = firmware_profile("erob", firmware).quirks
    device = ErobCanopenBus()
    front = CanopenFront(ErobFirmware(profile("eRob80H100"), NODE, quirks=frozenset(quirks)), NODE)
    device.add(front)
    device.tick(0.001)
    network = LoopNetwork(device.on_frame)
    node = canopen.RemoteNode(NODE, canopen.import_od(str(vendor_eds(tmp_path / "z.eds")), NODE))
    network.add_node(node)
    node.sdo[0x6060].raw = 1
    for cw in (0x06, 0x07, 0x0F):
        node.sdo[0x6040].raw = cw
    assert front.state.name == "OPERATION_ENABLED"
    if firmware is None:
        with pytest.raises(canopen.SdoAbortedError) as info:
            node.sdo[0x6060].raw = 8
        assert info.value.code == 0x08000022 and node.sdo[0x6061].raw == 1
    else:
        node.sdo[0x6060].raw = 8
        assert node.sdo[0x6061].raw == 8 and front.state.name == "OPERATION_ENABLED"


def test_the_twin_answers_as_its_export_says(tmp_path: Path) -> None:
    """Every object of the export reads with its type's size; every ro/const one refuses a write (0x06010002),
    every writable one takes its own value back."""
    path = tmp_path / "twin.eds"
    path.write_text(eds_text(NODE), encoding="utf-8")
    _world, _front, node = twin(path)
    od = node.object_dictionary
    checked = 0
    for obj in od.values():
        if obj.index < 0x1000:
            continue
        for var in ([obj] if isinstance(obj, canopen.objectdictionary.ODVariable) else obj.values()):
            data = node.sdo.upload(var.index, var.subindex)
            assert len(data) == max(1, len(var.encode_raw(0))), f"0x{var.index:04X}:{var.subindex:02X}"
            if not var.writable:
                with pytest.raises(canopen.SdoAbortedError) as info:
                    node.sdo.download(var.index, var.subindex, data)
                assert info.value.code == 0x06010002, f"0x{var.index:04X}:{var.subindex:02X}"
            elif not (0x1600 <= var.index < 0x1800 or 0x1A00 <= var.index < 0x1C00) and var.index != 0x6060:
                # a writable object takes its own value back (mapping entries only with sub-index 0 = 0 and the
                # PDO not valid, CiA 301; 0x6060 = 0 names no mode)
                node.sdo.download(var.index, var.subindex, data)
            checked += 1
    assert checked == sum(len(o["variables"]) for o in vendor()["objects"])
