"""Modbus RTU codec benchmark: joints vs pymodbus, and loopback transactions per second.

Run from the repository root::

    python tests/benchmarks/bench_modbus_codec.py [--repeats 5] [--min-time 0.2]

(a) One host-side transaction's codec work: build the full request frame (address, PDU, CRC) and
    parse a full reply frame (CRC check, framing, register values). joints: ``mb.encode`` +
    ``ModbusRtuCodec.feed``/``next_message``; pymodbus 3.x: ``FramerRTU.buildFrame`` of a request
    PDU + ``FramerRTU.handleFrame`` of the reply (a client-side ``DecodePDU``). Both get the same
    bytes, both construct their message objects each time, and the frames and decoded values are
    checked equal before timing. Messages: FC03 of 25 registers from 0x0060 (the eRob status
    block, ``ErobModbusDriver.state()``) and FC16 of 2 registers at 0x0047 (an int32 write).
(b) Whole transactions through ``ModbusLink`` + ``LoopbackTransport`` + ``ModbusDeviceBus`` /
    ``ModbusFront`` (host codec, link matching, device codec, register image, driver decode),
    as transactions per second and as a multiple of the pure host codec cost.

Timing: ``time.perf_counter`` around a loop of N iterations (N grown until one run lasts
``--min-time``), best of ``--repeats`` runs, reported per iteration. Not collected by pytest.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from joints.clock import ManualClock
from joints.codecs import modbus as mb
from joints.devices.erob.registers import EROB_MODBUS, STATUS_BLOCK_START, STATUS_BLOCK_WORDS
from joints.drivers.erob_modbus import ErobModbusDriver
from joints.link.modbus import ModbusLink, RetryPolicy
from joints.sim.firmware import Firmware
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.transports.loopback import LoopbackTransport

GOAL = 3.0  #: the issue's target: joints encode+decode at least 3x faster than pymodbus
SLAVE = 2
READ_ADDR, READ_COUNT = STATUS_BLOCK_START, STATUS_BLOCK_WORDS  # 0x0060, 25
WRITE_ADDR, WRITE_VALUES = 0x0047, (0x0000, 10000)  # profile_speed = 10000, Hi word first
STATUS_VALUES = tuple((0x1111 * (i + 1)) & 0xFFFF for i in range(READ_COUNT))

Bench = Callable[[int], None]


def calibrate(fn: Bench, min_time: float) -> int:
    """Iterations N such that one run of ``fn(N)`` lasts at least ``min_time``."""
    n = 1
    while True:
        t0 = time.perf_counter()
        fn(n)
        if time.perf_counter() - t0 >= min_time:
            return n
        n *= 2


def measure(fns: list[Bench], repeats: int, min_time: float) -> list[float]:
    """Best-of-``repeats`` seconds per iteration of each ``fn(n)``.

    The functions are timed in turn within each repeat (interleaved), so that a burst of load on
    the machine hits all of them alike instead of skewing one side of a ratio.
    """
    counts = [calibrate(fn, min_time) for fn in fns]
    best = [float("inf")] * len(fns)
    for _ in range(repeats):
        for i, (fn, n) in enumerate(zip(fns, counts)):
            t0 = time.perf_counter()
            fn(n)
            best[i] = min(best[i], (time.perf_counter() - t0) / n)
    return best


# --- joints ---------------------------------------------------------------------------------

REPLY03 = mb.encode(mb.ReadRegistersReply(SLAVE, mb.READ_HOLDING_REGISTERS, STATUS_VALUES))
REPLY16 = mb.encode(mb.WriteMultipleRegistersReply(SLAVE, WRITE_ADDR, len(WRITE_VALUES)))
REPLY06 = mb.encode(mb.WriteSingleRegisterReply(SLAVE, 0x0040, 3))


def joints_fc03(n: int) -> None:
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    encode, read_req, reply = mb.encode, mb.ReadHoldingRegisters, REPLY03
    for _ in range(n):
        req = read_req(SLAVE, READ_ADDR, READ_COUNT)
        encode(req)
        codec.expect_reply_to(req)
        codec.feed(reply)
        _ = codec.next_message().values  # type: ignore[union-attr]


def joints_fc16(n: int) -> None:
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    encode, write_req, reply = mb.encode, mb.WriteMultipleRegisters, REPLY16
    for _ in range(n):
        req = write_req(SLAVE, WRITE_ADDR, WRITE_VALUES)
        encode(req)
        codec.expect_reply_to(req)
        codec.feed(reply)
        codec.next_message()


def joints_fc06(n: int) -> None:
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    encode, write_req, reply = mb.encode, mb.WriteSingleRegister, REPLY06
    for _ in range(n):
        req = write_req(SLAVE, 0x0040, 3)
        encode(req)
        codec.expect_reply_to(req)
        codec.feed(reply)
        codec.next_message()


def joints_encode03(n: int) -> None:
    encode, read_req = mb.encode, mb.ReadHoldingRegisters
    for _ in range(n):
        encode(read_req(SLAVE, READ_ADDR, READ_COUNT))


def joints_decode03(n: int) -> None:
    codec = mb.ModbusRtuCodec(mb.Role.HOST)
    req = mb.ReadHoldingRegisters(SLAVE, READ_ADDR, READ_COUNT)
    for _ in range(n):
        codec.expect_reply_to(req)
        codec.feed(REPLY03)
        _ = codec.next_message().values  # type: ignore[union-attr]


# --- pymodbus -------------------------------------------------------------------------------


def pymodbus_benches() -> dict[str, Bench] | None:
    try:
        import pymodbus
        from pymodbus.framer import FramerRTU
        from pymodbus.pdu import DecodePDU
        from pymodbus.pdu.register_message import (
            ReadHoldingRegistersRequest,
            WriteMultipleRegistersRequest,
        )
    except ImportError:
        return None

    def framer() -> FramerRTU:
        return FramerRTU(DecodePDU(False))  # client side: decodes responses

    # like with like: the same frames out, the same values in
    f = framer()
    frame03 = f.buildFrame(ReadHoldingRegistersRequest(address=READ_ADDR, count=READ_COUNT, dev_id=SLAVE))
    frame16 = f.buildFrame(WriteMultipleRegistersRequest(address=WRITE_ADDR, registers=list(WRITE_VALUES), dev_id=SLAVE))
    assert frame03 == mb.encode(mb.ReadHoldingRegisters(SLAVE, READ_ADDR, READ_COUNT)), frame03.hex(" ")
    assert frame16 == mb.encode(mb.WriteMultipleRegisters(SLAVE, WRITE_ADDR, WRITE_VALUES)), frame16.hex(" ")
    used, pdu = f.handleFrame(REPLY03, SLAVE, 0)
    assert used == len(REPLY03) and tuple(pdu.registers) == STATUS_VALUES  # type: ignore[union-attr]
    used, pdu = f.handleFrame(REPLY16, SLAVE, 0)
    assert used == len(REPLY16) and (pdu.address, pdu.count) == (WRITE_ADDR, 2)  # type: ignore[union-attr]

    def pymodbus_fc03(n: int) -> None:
        fr = framer()
        build, handle, req_cls, reply = fr.buildFrame, fr.handleFrame, ReadHoldingRegistersRequest, REPLY03
        for _ in range(n):
            build(req_cls(address=READ_ADDR, count=READ_COUNT, dev_id=SLAVE))
            _ = handle(reply, SLAVE, 0)[1].registers  # type: ignore[union-attr]

    def pymodbus_fc16(n: int) -> None:
        fr = framer()
        build, handle, req_cls, reply = fr.buildFrame, fr.handleFrame, WriteMultipleRegistersRequest, REPLY16
        for _ in range(n):
            build(req_cls(address=WRITE_ADDR, registers=list(WRITE_VALUES), dev_id=SLAVE))
            handle(reply, SLAVE, 0)

    def pymodbus_encode03(n: int) -> None:
        build = framer().buildFrame
        for _ in range(n):
            build(ReadHoldingRegistersRequest(address=READ_ADDR, count=READ_COUNT, dev_id=SLAVE))

    def pymodbus_decode03(n: int) -> None:
        handle = framer().handleFrame
        for _ in range(n):
            _ = handle(REPLY03, SLAVE, 0)[1].registers  # type: ignore[union-attr]

    pymodbus_fc03.version = pymodbus.__version__  # type: ignore[attr-defined]
    return {
        "fc03": pymodbus_fc03,
        "fc16": pymodbus_fc16,
        "encode03": pymodbus_encode03,
        "decode03": pymodbus_decode03,
    }


# --- loopback -------------------------------------------------------------------------------


def loopback_driver() -> tuple[ErobModbusDriver, Firmware]:
    slave = ModbusFront.plain(EROB_MODBUS, SLAVE, values={"actual_position": -123456, "status_of_achieving_position": 1})
    link = ModbusLink(LoopbackTransport(ModbusDeviceBus([slave])), policy=RetryPolicy(timeout=0.1, retries=0))
    return ErobModbusDriver(link, SLAVE, clock=ManualClock()), slave.firmware


def loop_state(n: int) -> None:
    driver, _ = loopback_driver()
    state = driver.state
    for _ in range(n):
        state()


def loop_write(n: int) -> None:
    driver, slave = loopback_driver()
    write = driver.write
    for _ in range(n):
        write("operation_mode", 3)  # FC06, validated and logged by the slave
    slave.write_log.clear()


def loop_read_registers(n: int) -> None:
    driver, _ = loopback_driver()
    read = driver.link.read_registers
    for _ in range(n):
        read(SLAVE, READ_ADDR, READ_COUNT)


# --- report ---------------------------------------------------------------------------------


def us(seconds: float) -> str:
    return f"{seconds * 1e6:9.2f} us"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5, help="timed runs per case; the best counts (default 5)")
    ap.add_argument("--min-time", type=float, default=0.2, help="seconds per timed run (default 0.2)")
    args = ap.parse_args(argv)
    def run(*fns: Bench) -> list[float]:
        return measure(list(fns), args.repeats, args.min_time)

    print(f"Python {platform.python_version()} ({platform.python_implementation()}) on {platform.machine()}, "
          f"best of {args.repeats} interleaved runs of >= {args.min_time:.2f} s each")
    pyb = pymodbus_benches()

    print("\n(a) codec cost per host transaction: request encode + reply decode (full RTU frames with CRC)")
    if pyb is None:
        j03, j16 = run(joints_fc03, joints_fc16)
        print("    pymodbus not installed: joints only")
        print(f"    FC03 x{READ_COUNT:<3}  joints {us(j03)}")
        print(f"    FC16 x{len(WRITE_VALUES):<3}  joints {us(j16)}")
    else:
        print(f"    pymodbus {pyb['fc03'].version}: FramerRTU.buildFrame + FramerRTU.handleFrame")  # type: ignore[attr-defined]
        j03, p03 = run(joints_fc03, pyb["fc03"])
        j16, p16 = run(joints_fc16, pyb["fc16"])
        je, pe = run(joints_encode03, pyb["encode03"])
        jd, pd = run(joints_decode03, pyb["decode03"])
        print(f"    {'message':<24}{'joints':>13}{'pymodbus':>13}   ratio")
        rows = [
            (f"FC03 x{READ_COUNT} (state block)", j03, p03),
            (f"FC16 x{len(WRITE_VALUES)} (int32 write)", j16, p16),
            ("  FC03 encode only", je, pe),
            ("  FC03 decode only", jd, pd),
        ]
        for label, j, p in rows:
            print(f"    {label:<24}{us(j):>13}{us(p):>13}   {p / j:5.1f}x")
        both = (p03 + p16) / (j03 + j16)
        worst = min(p03 / j03, p16 / j16)
        print(f"    FC03: joints is {p03 / j03:.1f}x faster than pymodbus")
        print(f"    FC16: joints is {p16 / j16:.1f}x faster than pymodbus")
        print(f"    FC03+FC16: joints is {both:.1f}x faster than pymodbus")
        print(f"    goal >= {GOAL:.1f}x on each message: {'MET' if worst >= GOAL else 'NOT MET'} (worst {worst:.1f}x)")

    print("\n(b) loopback transactions: ModbusLink + LoopbackTransport + ModbusDeviceBus/ModbusFront")
    j06, ls, lr, lw = run(joints_fc06, loop_state, loop_read_registers, loop_write)
    for label, t, codec in (
        (f"driver.state() (FC03 x{READ_COUNT})", ls, j03),
        (f"link.read_registers x{READ_COUNT}", lr, j03),
        ("driver.write() (FC06)", lw, j06),
    ):
        print(f"    {label:<32}{us(t)}  {1 / t:9.0f} tx/s  = {t / codec:4.1f}x the pure host codec cost ({us(codec).strip()})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
