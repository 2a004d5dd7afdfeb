"""The canopen package's BaseNode402 as an independent master of our twin: in process over python-can's ``virtual``
channel (the world paced in real time: that master waits on the wall clock) and across processes against
`joints sim serve` on udp_multicast. Every wait is on a condition with a bounded timeout."""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

canopen = pytest.importorskip("canopen")
pytest.importorskip("mujoco")

import can

import simkit
from joints.devices.erob.eds import eds_text
from joints.devices.erob.profiles import profile
from joints.sim.can_serve import client_bus
from simkit import served_can

SERVED = """
backend = "sim"
[sim]
model = "erob_stand.xml"
[buses.can]
protocol = "canopen"
[joints.joint1]
device = "erob"
model = "eRob80H100"
bus = "can"
address = 2
"""


def write_eds(path: Path, node: int) -> Path:
    """The twin's EDS (joints.devices.erob.eds) as a file, for the canopen package."""
    path.write_text(eds_text(node), encoding="utf-8")
    return path


#: the wall-clock waits bound a failure only: a loaded machine holds a process back for seconds (docs/speed.md,
#: g5-house: a served reply once 7 s late at run queue 8-9), so each bound is this many times what the drive needs
SLACK = 10.0


def wait_until(cond: Callable[[], Any], timeout: float, what: str) -> None:
    timeout *= SLACK
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.005)


@pytest.fixture
def twin(tmp_path: Path) -> Iterator[tuple[Any, str, Path]]:
    world = simkit.world("erob_stand.xml", [simkit.drive("joint1", 2, profile("eRob80H100"), bus="can",
                                                         protocol="canopen")])
    device = world.buses["can"]
    channel = f"joints-co-{os.getpid()}-{id(world)}"
    side = can.Bus(interface="virtual", channel=channel)
    tap = device.medium.attach("tap")
    stop = threading.Event()

    def run() -> None:  # the world in real time; frames in and out between physics steps
        t0, s0 = time.monotonic(), world.time
        while not stop.is_set():
            while (m := side.recv(0)) is not None:
                for a in device.on_frame(m):
                    side.send(a)
            behind = (time.monotonic() - t0) - (world.time - s0)
            if behind > world.timestep:
                world.step(min(50, int(behind / world.timestep)))
            while tap.rx:
                f = tap.rx.popleft()
                side.send(can.Message(arbitration_id=f.arbitration_id, data=f.data, is_extended_id=False,
                                      is_remote_frame=f.is_remote_frame, dlc=f.dlc))
            time.sleep(0.0003)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        yield world, channel, write_eds(tmp_path / "erob.eds", 2)
    finally:
        stop.set()
        thread.join(5)
        side.shutdown()


def reset_communication(network: Any, eds: Path) -> Any:
    """Node 2 as a BaseNode402, after NMT reset communication and its boot-up.

    The eRob boots within 1 ms of the reset (eRunner figs 5-18, 5-23, 5-27), possibly before canopen's
    ``wait_for_bootup`` has started listening: listen from before the command instead."""
    node = canopen.BaseNode402(2, str(eds))
    network.add_node(node)
    booted = threading.Event()

    def on_boot(can_id: int, data: bytearray, timestamp: float) -> None:
        if bytes(data) == b"\x00":
            booted.set()

    network.subscribe(0x702, on_boot)
    node.nmt.state = "RESET COMMUNICATION"
    assert booted.wait(2.0 * SLACK), f"no boot-up within {2.0 * SLACK} s of the NMT reset communication"
    network.unsubscribe(0x702, on_boot)
    return node


def pp_move_and_pv_run(network: Any, eds: Path) -> Any:
    """The master's script: bring-up, PP move to 50000 counts, PV run at 30000 counts/s after SWITCHED ON."""
    node = reset_communication(network, eds)
    node.sdo[0x1800][5].raw = 10  # TPDO1 (statusword) every 10 ms as well as on change
    node.sdo[0x1017].raw = 100
    node.setup_402_state_machine()
    node.nmt.state = "OPERATIONAL"
    node.op_mode = "PROFILED POSITION"
    assert node.sdo[0x6061].raw == 1
    node.state = "OPERATION ENABLED"
    assert node.state == "OPERATION ENABLED"
    node.sdo[0x6081].raw = 100000  # profile velocity [count/s]
    node.sdo[0x6083].raw = 400000
    node.sdo[0x6084].raw = 400000
    node.sdo[0x607A].raw = 50000
    node.controlword = 0x3F  # enable operation + new set-point + change set immediately
    wait_until(lambda: node.statusword & 0x1000, 1.0, "set-point acknowledge")
    node.controlword = 0x2F
    wait_until(lambda: node.statusword & 0x0400 and abs(node.sdo[0x6064].raw - 50000) < 200, 5.0,
               "target reached at 50000")
    # PV after going to SWITCHED ON: the mode changes, enable again, run
    node.state = "SWITCHED ON"
    node.op_mode = "PROFILED VELOCITY"
    assert node.sdo[0x6061].raw == 3
    node.state = "OPERATION ENABLED"
    node.sdo[0x60FF].raw = 30000
    wait_until(lambda: abs(node.sdo[0x606C].raw - 30000) < 1500, 5.0, "velocity 30000 count/s")
    node.sdo[0x60FF].raw = 0
    wait_until(lambda: abs(node.sdo[0x606C].raw) < 500, 5.0, "standstill")
    return node


def test_basenode402_pp_move_and_pv_run(twin: tuple[Any, str, Path]) -> None:
    _world, channel, eds = twin
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    try:
        node = pp_move_and_pv_run(network, eds)
        node.state = "SWITCH ON DISABLED"
    finally:
        network.disconnect()


def test_basenode402_runs_csv_on_its_own_sync_and_periodic_rpdo(twin: tuple[Any, str, Path]) -> None:
    """CSV driven the CiA 402 way by canopen's master: RPDO1 (controlword + 0x60FF) and TPDO1 (statusword + 0x606C)
    mapped synchronous (type 1) through canopen's PDO API, a 10 ms SYNC of its SyncProducer and the RPDO sent
    periodically (BaseNode402 itself never sends a synchronous RPDO); the twin applies each RPDO at the SYNC."""
    _world, channel, eds = twin
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    try:
        node = reset_communication(network, eds)
        node.sdo[0x1006].raw = 10_000  # communication cycle period [us]
        node.rpdo.read()
        node.tpdo.read()
        rpdo, tpdo = node.rpdo[1], node.tpdo[1]
        rpdo.clear()
        rpdo.add_variable(0x6040)
        rpdo.add_variable(0x60FF)
        rpdo.trans_type = 1
        rpdo.enabled = True
        tpdo.clear()
        tpdo.add_variable(0x6041)
        tpdo.add_variable(0x606C)
        tpdo.trans_type = 1
        tpdo.enabled = True
        rpdo.save()
        tpdo.save()
        assert node.sdo[0x1600][2].raw == 0x60FF0020 and node.sdo[0x1400][2].raw == 1
        node.setup_402_state_machine(read_pdos=False)
        node.op_mode = "CYCLIC SYNCHRONOUS VELOCITY"
        assert node.sdo[0x6061].raw == 9
        node.nmt.state = "OPERATIONAL"
        rpdo[0x60FF].raw = 0
        rpdo.start(0.01)
        network.sync.start(0.01)
        wait_until(lambda: tpdo.is_received, 1.0, "TPDO1 on SYNC")
        node.state = "OPERATION ENABLED"
        wait_until(lambda: node.statusword & 0x1000, 2.0, "bit 12: the drive follows the target (brake released)")
        rpdo[0x60FF].raw = 40_000  # count/s
        wait_until(lambda: abs(tpdo[0x606C].raw - 40_000) < 1500, 5.0, "velocity 40000 count/s in TPDO1")
        rpdo[0x60FF].raw = 0
        wait_until(lambda: abs(tpdo[0x606C].raw) < 500, 5.0, "standstill")
        node.state = "SWITCH ON DISABLED"
    finally:
        network.sync.stop()
        network.disconnect()


@pytest.mark.skipif(sys.platform == "win32", reason="udp_multicast serving is tested on POSIX")
def test_basenode402_across_processes_and_what_the_twin_sends_by_itself(tmp_path: Path) -> None:
    """Against `joints sim serve`: boot-up, event TPDOs and heartbeats come from the served world's own clock
    (forwarded from the twins' medium); life guarding that the master lets lapse is EMCY 0x8130 and FAULT; a
    fault reset by the master clears it (EMCY 0x0000)."""
    pytest.importorskip("msgpack")
    cfg = tmp_path / "sim.toml"
    cfg.write_text(SERVED)
    eds = write_eds(tmp_path / "erob.eds", 2)
    t0 = time.monotonic()
    with served_can(cfg) as line:
        assert line["interface"] == "udp_multicast"
        bus = client_bus(line)
        network = canopen.Network(bus).connect()
        try:
            node = pp_move_and_pv_run(network, eds)  # needs the forwarded boot-up and event TPDOs
            assert node.nmt.wait_for_heartbeat(1.0 * SLACK) == "OPERATIONAL"  # 0x1017 = 100 ms
            assert bus.echoes_dropped > 0  # udp_multicast returned the master's own frames: never seen
            # life guarding: 50 ms x 4; the master guards, then stops
            node.sdo[0x100C].raw = 50
            node.sdo[0x100D].raw = 4
            node.nmt.start_node_guarding(0.05)
            wait_until(lambda: node.nmt.state == "OPERATIONAL", 1.0, "a guarding reply")
            assert node.state == "OPERATION ENABLED"  # guarded in time: no fault
            node.nmt.stop_node_guarding()
            wait_until(lambda: any(e.code == 0x8130 for e in node.emcy.log), 3.0, "EMCY 0x8130 (life guarding)")
            wait_until(lambda: node.state == "FAULT", 1.0, "FAULT in the statusword TPDO")
            node.sdo[0x100C].raw = 0  # guarding off, then fault reset (rising bit 7)
            node.controlword = 0x00
            node.controlword = 0x80
            wait_until(lambda: node.state == "SWITCH ON DISABLED", 1.0, "SWITCH ON DISABLED after the fault reset")
            wait_until(lambda: node.emcy.log[-1].code == 0x0000, 1.0, "EMCY 0x0000 (error reset)")
            assert node.sdo[0x603F].raw == 0
        finally:
            network.disconnect()
    assert time.monotonic() - t0 < 60
