"""The ZLAC8015D twin's fast paths give the reference's bits, and are taken.

* The status block (0x20A2 .. 0x20AF, the one FC03 a host reads every step) is served by one call
  (:meth:`ZlacFirmware._read_status`) instead of the generic reader's twelve ``computed`` functions.
* A write block of only ramp times and target velocities refreshes only the ramp-time columns
  (:meth:`ZlacFirmware._cache_ramps`) instead of every loop constant (:meth:`ZlacFirmware._cache`).

The reference is the same twin with both turned off (the generic reader, the full cache); the same
frames and substeps must give the same register words and kernel rows, bit for bit, sensor noise included.
"""

from __future__ import annotations

import math
from typing import Any

import pytest

from joints.codecs import modbus as mb
from joints.devices.zlac.profile import HubMotorProfile
from joints.devices.zlac.registers import ZLAC8015D, Fault
from joints.drivers.zlac_modbus import STATUS_START, STATUS_WORDS
from joints.sim import zlac
from joints.sim.firmware import Firmware
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.sim.zlac import ZlacFirmware

DT = 1e-3
J = 0.05  #: kg*m^2 per wheel of the integrated plant


class Run:
    """One twin on a bus, its wheels integrated here; counts the calls of the fast paths."""

    def __init__(self) -> None:
        self.fw = ZlacFirmware(HubMotorProfile(), 1)
        self.calls = {"_read_status": 0, "_cache_ramps": 0, "_cache": 0}
        for name in self.calls:
            self._count(name)
        self.bus = ModbusDeviceBus([ModbusFront(self.fw, ZLAC8015D, node_id="rs485_node_id")])
        self.q = [0.0, 0.0]
        self.qd = [0.0, 0.0]
        self.t = 0.0
        self.record: list[Any] = []

    def _count(self, name: str) -> None:
        method = getattr(self.fw, name)

        def counted(*args: Any) -> Any:
            self.calls[name] += 1
            return method(*args)

        setattr(self.fw, name, counted)

    def send(self, req: mb.Request) -> None:
        reply = self.bus.exchange(req)
        self.record.append(reply)

    def write(self, address: int, *values: int) -> None:
        self.send(mb.WriteMultipleRegisters(1, address, tuple(v & 0xFFFF for v in values)))

    def status(self) -> None:
        self.send(mb.ReadHoldingRegisters(1, STATUS_START, STATUS_WORDS))

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / DT)):
            self.t += DT
            for i, ch in enumerate(self.fw.channels):
                tau = ch.step(self.t, DT, self.q[i], self.qd[i])
                self.qd[i] += (tau - 0.02 * self.qd[i]) / J * DT
                self.q[i] += self.qd[i] * DT
            self.record.append(tuple(tuple(row) for row in self.fw.kernel_rows()))
            if round(self.t / DT) % 20 == 0:
                self.status()


def scenario(r: Run) -> None:
    """Velocity mode driven as a host drives it: ramps and targets in one or two FC16s, a status read
    every 20 ms, a block written by name in an odd order, a setting beside ramps, a quick stop."""
    r.write(0x200D, 3)  # velocity mode
    r.write(0x200E, 0x08)  # enable
    r.run(0.05)
    for k, (left, right, ms) in enumerate([(60, -40, 200), (120, 80, 350), (-90, 30, 50), (0, 0, 400), (200, -200, 0)]):
        r.write(0x2080, ms, ms + 7, ms + 3, ms + 11)  # acceleration L/R, deceleration L/R
        r.write(0x2088, left, right)
        r.run(0.07 + 0.01 * k)
        r.status()
    r.write(0x2080, 120, 130, 140, 150, 0, 0, 0, 0, 30, -30)  # ramps .. targets in one block
    r.run(0.1)
    r.fw.write_many((("acceleration_time_left", 600), ("target_velocity_left", -150),
                     ("deceleration_time_left", 40)))  # by name: the target reads the block's ramps
    r.run(0.1)
    r.fw.write_many((("acceleration_time_right", 90), ("vl_kp_right", 450), ("target_velocity_right", 100)))
    r.run(0.1)
    r.write(0x200E, 0x05)  # quick stop
    r.run(0.1)
    r.write(0x2080, 250, 250, 250, 250)
    r.write(0x200E, 0x08)
    r.run(0.1)
    r.status()


def _reference(monkeypatch: pytest.MonkeyPatch) -> Run:
    with monkeypatch.context() as m:
        m.setattr(zlac, "_LIGHT", frozenset())  # every block takes the full cache
        m.setattr(zlac, "_STATUS", ())  # no block is the status block: the generic reader
        ref = Run()
        scenario(ref)
    return ref


def test_the_fast_paths_give_the_reference_bits_and_are_taken(monkeypatch: pytest.MonkeyPatch) -> None:
    ref = _reference(monkeypatch)
    fast = Run()
    scenario(fast)
    assert fast.fw.sensors[0].model.ideal is False  # the noise (one random stream per wheel) is in the comparison
    assert ref.calls["_read_status"] == 0 and ref.calls["_cache_ramps"] == 0
    assert fast.calls["_read_status"] > 20, fast.calls  # taken: every status read
    assert fast.calls["_cache_ramps"] >= 6, fast.calls  # taken: every ramp block without another setting
    assert fast.calls["_cache"] < ref.calls["_cache"]
    assert len(fast.record) == len(ref.record)
    for i, (a, b) in enumerate(zip(fast.record, ref.record)):
        assert a == b, f"record {i}: {a} != {b}"
    assert fast.fw.values == ref.fw.values


def test_the_status_reader_is_the_generic_one_for_the_same_state() -> None:
    """Drive by drive state (disabled, running, faulted, quick stop): the one-call reader and the generic
    reader give the same values from the same state and the same random streams."""
    r = Run()
    fast = r.fw.reader(zlac._STATUS)
    generic = Firmware.reader(r.fw, zlac._STATUS)
    assert fast is not generic

    def both() -> None:
        saved = [(s.rng.getstate(), s._age, s._age_t) for s in r.fw.sensors]
        a = fast()
        for s, (state, age, age_t) in zip(r.fw.sensors, saved):
            s.rng.setstate(state)
            s._age, s._age_t = age, age_t
        b = generic()
        assert a == b

    both()
    r.write(0x200D, 3)
    r.write(0x200E, 0x08)
    r.write(0x2088, 300, -250)
    for _ in range(5):
        r.run(0.03)
        both()
    r.fw.left.temperature = 400.0  # saturates the packed byte
    r.fw.raise_fault(r.fw.right, Fault.OVER_LOAD)
    both()
    r.write(0x200E, 0x06)
    r.write(0x200E, 0x08)
    r.write(0x200E, 0x05)
    r.run(0.02)
    both()


def test_a_replaced_computed_parameter_is_served_by_the_generic_reader() -> None:
    fw = ZlacFirmware(HubMotorProfile(), 1)
    fw.computed["motor_temperature"] = lambda: 0x1234
    front = ModbusFront(fw, ZLAC8015D, node_id="rs485_node_id")
    words = front.read(STATUS_START, STATUS_WORDS)
    assert words[0x20A4 - STATUS_START] == 0x1234


@pytest.mark.parametrize("value", [0, 1, 32767, 32768, -1, 1.0, 2.5, True, math.nan, "3"])
def test_a_register_check_is_check_value(value: Any) -> None:
    from joints.devices.params import check_value
    from joints.errors import CommandError

    reg = ZLAC8015D.get("acceleration_time_left")  # 0..32767 ms
    try:
        want: Any = check_value(reg.name, reg.type, value, reg.minimum, reg.maximum, reg.unit, f" (0x{reg.address:04X})")
    except CommandError as exc:
        want = str(exc)
    try:
        got: Any = reg.check(value)
    except CommandError as exc:
        got = str(exc)
    assert got == want and type(got) is type(want)
