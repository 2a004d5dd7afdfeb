"""The canopen package's BaseNode402 as an independent master of our twin, in process over python-can's
``virtual`` channel (the world paced in real time: that master waits on the wall clock). Every wait is on a
condition with a bounded timeout."""

from __future__ import annotations

import os
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
from joints.devices.erob.profiles import profile
from joints.sim.erob_canopen import write_eds


def wait_until(cond: Callable[[], bool], timeout: float, what: str) -> None:
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


def test_basenode402_pp_move_and_pv_run(twin: tuple[Any, str, Path]) -> None:
    _world, channel, eds = twin
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    try:
        node = canopen.BaseNode402(2, str(eds))
        network.add_node(node)
        node.nmt.state = "RESET COMMUNICATION"
        node.nmt.wait_for_bootup(2.0)
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
        node.state = "SWITCH ON DISABLED"
    finally:
        network.disconnect()
