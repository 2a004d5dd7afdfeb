"""The ZLAC8015D twin (joints.sim.zlac firmware + Modbus front) and the hub-motor profile, without MuJoCo.

Each wheel is a rigid body integrated here (J dq/dt = tau - b*qd - coulomb*sign(qd) + load,
q += qd*dt, dt = 1 ms); the drive is reached only through Modbus RTU frames on a
:class:`ModbusDeviceBus` (frames built with :func:`joints.codecs.modbus.encode` or replayed from the
manual's vectors). Replies that do not depend on motion must be byte-exact. The last test couples
the emulator to ``models/zlac_diffdrive.xml`` and is skipped without MuJoCo.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from joints.codecs import modbus as mb
from joints.devices.zlac.profile import DEFAULT_MODEL, PROFILES, HubMotorProfile, profile
from joints.devices.zlac.registers import (
    STATUS_BLOCK_START,
    STATUS_BLOCK_WORDS,
    ZLAC8015D,
    Fault,
    split_left_right,
)
from joints.errors import ConfigError
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.sim.sensors import IDEAL
from joints.sim.zlac import DriveState, ZlacFirmware

ROOT = Path(__file__).resolve().parents[2]
from testdata import VECTORS

RPM = 2 * math.pi / 60
PROFILE = HubMotorProfile()
DT = 1e-3
CPR = 4096
SIDES = ("left", "right")


# ------------------------------------------------------------------------------------ bench


def front(emu: ZlacFirmware) -> ModbusFront:
    """The drive's Modbus front: its slave address is the node id held at power-on."""
    return ModbusFront(emu, ZLAC8015D, node_id="rs485_node_id")


@dataclass
class Sample:
    t: float
    regs: dict[str, int]


class Bench:
    """One emulated drive on a bus, two wheels integrated here, a host that polls every 50 ms."""

    def __init__(
        self,
        *,
        inertia: float | None = None,
        own: float | None = None,
        damping: float = PROFILE.viscous_friction,
        coulomb: float = PROFILE.coulomb_friction,
        address: int = 1,
        **kw: Any,
    ) -> None:
        prof = kw.pop("profile", PROFILE)
        self.emu = ZlacFirmware(prof, address, inertia_left=own, inertia_right=own, **kw)
        self.front = front(self.emu)
        self.bus = ModbusDeviceBus([self.front])
        self.address = address
        j = inertia if inertia is not None else PROFILE.tuning_inertia
        self.J = [j, j]
        self.b = [damping, damping]
        self.c = [coulomb, coulomb]
        self.load = [0.0, 0.0]  #: external torque on each wheel [N*m]
        self.blocked = [False, False]  #: wheel held still (a wall)
        self.q = [0.0, 0.0]
        self.qd = [0.0, 0.0]
        self.tau = [0.0, 0.0]
        self.n = 0
        self.trace: list[tuple[float, float, float, float, float]] = []  #: t, qd_l, qd_r, tau_l, tau_r
        self.samples: list[Sample] = []
        self.poll = 0.05  #: s between status polls (None: the host is silent)

    @property
    def t(self) -> float:
        return self.n * DT

    def state(self) -> DriveState:
        return self.emu.state

    # -- Modbus host side ---------------------------------------------------------------------
    def send(self, frame: bytes) -> bytes:
        return self.bus.receive(frame)

    def request(self, req: mb.Request) -> bytes:
        return self.send(mb.encode(req))

    def write(self, name: str, value: int) -> bytes:
        reg = ZLAC8015D.get(name)
        words = reg.to_words(value)
        if len(words) == 1:
            return self.request(mb.WriteSingleRegister(self.address, reg.address, words[0]))
        return self.request(mb.WriteMultipleRegisters(self.address, reg.address, words))

    def write_words(self, address: int, values: tuple[int, ...]) -> bytes:
        return self.request(mb.WriteMultipleRegisters(self.address, address, tuple(v & 0xFFFF for v in values)))

    def read_words(self, start: int, count: int) -> tuple[int, ...]:
        reply = self.request(mb.ReadHoldingRegisters(self.address, start, count))
        assert reply[1] == 0x03, reply.hex(" ")
        assert reply == mb.encode(mb.ReadRegistersReply(self.address, 3, tuple(
            int.from_bytes(reply[3 + 2 * i:5 + 2 * i], "big") for i in range(count)))), "CRC/format"
        return tuple(int.from_bytes(reply[3 + 2 * i:5 + 2 * i], "big") for i in range(count))

    def read(self, name: str) -> int:
        reg = ZLAC8015D.get(name)
        return reg.from_words(self.read_words(reg.address, reg.words))

    def status(self) -> dict[str, int]:
        words = self.read_words(STATUS_BLOCK_START, STATUS_BLOCK_WORDS)
        out: dict[str, int] = {}
        for reg in ZLAC8015D:
            off = reg.address - STATUS_BLOCK_START
            if 0 <= off and off + reg.words <= STATUS_BLOCK_WORDS:
                out[reg.name] = reg.from_words(words[off:off + reg.words])
        return out

    def exception_code(self, reply: bytes) -> int | None:
        return reply[2] if reply[1] & 0x80 else None

    # -- configuration shortcuts -----------------------------------------------------------------
    def velocity_mode(self, accel_ms: int = 500, decel_ms: int = 500) -> None:
        for side in SIDES:
            self.write(f"acceleration_time_{side}", accel_ms)
            self.write(f"deceleration_time_{side}", decel_ms)
        self.write("control_mode", 3)
        self.write("control_word", 0x08)

    def position_mode(self, mode: int = 1, sync: int = 0, speed: int = 50) -> None:
        self.write("synchronous_asynchronous_control_status", sync)
        self.write("control_mode", mode)
        for side in SIDES:
            self.write(f"target_speed_{side}", speed)
        self.write("control_word", 0x08)

    # -- physics ----------------------------------------------------------------------------------
    def run(self, seconds: float, until: Callable[[Bench], bool] | None = None) -> None:
        steps = round(seconds / DT)
        poll_every = round(self.poll / DT) if self.poll else 0
        chans = (self.emu.left, self.emu.right)
        for _ in range(steps):
            self.n += 1
            t = self.n * DT
            for i, ch in enumerate(chans):
                tau = ch.step(t, DT, self.q[i], self.qd[i])
                self.tau[i] = tau
                if self.blocked[i]:
                    self.qd[i] = 0.0
                    continue
                net = tau - self.b[i] * self.qd[i] + self.load[i]
                c = self.c[i]
                if c:
                    if abs(self.qd[i]) > 1e-6:
                        net -= math.copysign(c, self.qd[i])
                    elif abs(net) <= c:
                        net, self.qd[i] = 0.0, 0.0
                    else:
                        net -= math.copysign(c, net)
                self.qd[i] += net / self.J[i] * DT
                self.q[i] += self.qd[i] * DT
            self.trace.append((t, self.qd[0], self.qd[1], self.tau[0], self.tau[1]))
            if poll_every and self.n % poll_every == 0:
                self.samples.append(Sample(t, self.status()))
            if until is not None and until(self):
                return

    def rpm(self, i: int) -> float:
        return self.qd[i] / RPM

    def counts(self, i: int) -> float:
        return self.q[i] * CPR / (2 * math.pi)


def crossing(trace: list[tuple[float, float, float, float, float]], col: int, level: float, t0: float) -> float:
    """First time after t0 when trace column ``col`` (rad/s) reaches ``level`` (same sign)."""
    for row in trace:
        if row[0] > t0 and (row[col] - level) * math.copysign(1.0, level) >= 0.0:
            return row[0] - t0
    raise AssertionError(f"level {level} never reached")


def vectors() -> list[dict[str, Any]]:
    if not VECTORS.exists():
        return []
    return list(json.loads(VECTORS.read_text()))


def zlac_sequences() -> dict[str, dict[str, Any]]:
    return {r["id"]: r for r in vectors() if r.get("record_type") == "sequence" and r["id"].startswith("seq-zlac")}


def hexbytes(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


# ------------------------------------------------------------------------------------ profile


def test_profile_defaults_and_derived_values() -> None:
    p = profile()
    assert p is PROFILES[DEFAULT_MODEL] and p.model == "ZLLG80ASM250" == DEFAULT_MODEL
    assert profile("zllg80asm250") is p
    assert p.torque_constant == 0.8 and p.pole_pairs == 15 and p.encoder_lines == 1024
    assert (p.rated_current, p.max_current) == (15.0, 30.0)  # driver defaults 0x2033/0x2034
    assert (p.motor_rated_current, p.motor_max_current) == (6.0, 11.0)  # the motor's own ratings
    assert p.counts_per_rev == CPR
    assert p.max_speed_rpm == pytest.approx(1000.0)
    assert p.no_load_speed == pytest.approx(262 * RPM)
    assert p.wheel_radius == 0.1016
    assert p.armature == p.rotor_inertia  # direct drive
    assert 0.005 < p.rotor_inertia < 0.03
    assert p.max_torque == pytest.approx(24.0)
    assert p.rated_torque == pytest.approx(12.0) and p.motor_rated_torque == pytest.approx(4.8)
    assert p.tuning_inertia == pytest.approx(p.rotor_inertia + p.load_inertia)
    assert p.back_emf_constant * p.no_load_speed == pytest.approx(p.rated_voltage)
    assert p.torque_from_current(2.0) == pytest.approx(1.6) and p.current_from_torque(1.6) == pytest.approx(2.0)
    assert p.wheel_speed(100) == pytest.approx(100 * RPM * 0.1016)
    assert p.coulomb_friction >= 0 and p.viscous_friction >= 0
    with pytest.raises(ConfigError) as e:
        profile("ZLLG65")
    assert "ZLLG80ASM250" in str(e.value)


def test_profile_sources_name_every_field_with_a_kind() -> None:
    p = HubMotorProfile()
    fields = [f for f in HubMotorProfile.__dataclass_fields__ if f != "sources"]
    assert set(p.sources) == set(fields)
    for name, text in p.sources.items():
        assert text.split()[0].rstrip(":?").split("/")[0] in {"PUB", "CFG", "EST", "MEAS"}, (name, text)
    assert p.sources["rotor_inertia"].startswith("EST")


def test_profile_overrides_are_validated() -> None:
    p = HubMotorProfile()
    q = p.with_overrides(rated_current=6.0, max_current=11.0, wheel_radius=0.1)
    assert (q.rated_current, q.max_current, q.wheel_radius) == (6.0, 11.0, 0.1)
    assert q.max_torque == pytest.approx(8.8)
    assert q.sources["rated_current"].startswith("CFG") and p.sources["rated_current"].startswith("CFG driver")
    assert p.with_overrides() is p
    assert p.with_overrides(coulomb_friction=0).coulomb_friction == 0.0
    assert p.with_overrides(pole_pairs=10.0).pole_pairs == 10
    for bad in (
        {"nope": 1},
        {"torque_constant": 0},
        {"torque_constant": -1},
        {"rotor_inertia": float("nan")},
        {"wheel_radius": "big"},
        {"pole_pairs": 1.5},
        {"rated_current": 16.0},  # 0x2033 range 0-150 x 0.1 A
        {"max_current": 31.0},  # 0x2034 range 0-300 x 0.1 A
        {"max_current": 10.0},  # below the rated current
        {"max_speed": 1001 * RPM},  # 0x2008 range 1-1000 r/min
        {"encoder_lines": 8192},
        {"model": ""},
    ):
        with pytest.raises(ConfigError):
            p.with_overrides(**bad)
    with pytest.raises(ConfigError) as e:
        p.with_overrides(radius=0.1)
    assert "wheel_radius" in str(e.value)


# ------------------------------------------------------------------------- register image


def test_power_on_image_answers_byte_exact() -> None:
    b = Bench()
    # ramp times 0x2080-0x2085 (500, 500, 500, 500, 10, 10), torque slopes, velocity targets 0
    reply = b.request(mb.ReadHoldingRegisters(1, 0x2080, 10))
    assert reply == mb.encode(mb.ReadRegistersReply(1, 3, (500, 500, 500, 500, 10, 10, 300, 300, 0, 0)))
    reply = b.request(mb.ReadHoldingRegisters(1, 0x208E, 2))
    assert reply == mb.encode(mb.ReadRegistersReply(1, 3, (120, 120)))
    # status block at rest: no faults, positions, speeds or currents
    reply = b.request(mb.ReadHoldingRegisters(1, STATUS_BLOCK_START, STATUS_BLOCK_WORDS))
    assert reply == mb.encode(mb.ReadRegistersReply(1, 3, (0,) * 10))
    assert b.read("communication_offline_time") == 1000
    assert b.read("maximum_motor_speed") == 1000
    assert (b.read("rated_current_left"), b.read("maximum_current_right")) == (150, 300)
    assert b.read("encoder_line_left") == 1024 and b.read("poles_of_motor_right") == 15
    assert b.read("dc_voltage") == 2400
    assert b.read("quick_stop_control") == 6
    assert split_left_right(b.read("motor_temperature")) == (25, 25)
    assert b.read("motor_state") == 0
    assert b.read("software_connected_status") == 1  # a frame has been received
    hall_l, hall_r = split_left_right(b.read("hall_state"))
    assert hall_l in range(1, 7) and hall_r in range(1, 7)


def test_manual_examples_2_1_to_2_3() -> None:
    recs = {r["id"]: r for r in vectors() if r.get("device") == "zlac8015d"}
    if not recs:
        pytest.skip("vectors.json not available")
    b = Bench()

    def frame(rid: str) -> bytes:
        r = recs[rid]
        return hexbytes(r["correct_hex"] or r["hex"])

    # 2.2: write left target speed 100 r/min (echo)
    assert b.send(frame("zlac-modbus-2.2-ex-send")) == frame("zlac-modbus-2.2-ex-recv")
    # 2.3: write encoder lines 1024 and hall offset 0 (corrected reply: quantity high byte restored)
    assert b.send(frame("zlac-modbus-2.3-ex-send")) == frame("zlac-modbus-2.3-ex-recv")
    # 2.1: "the actual speed of motor is 10RPM": run both wheels at 10 r/min, then the reply is exact
    b.write_words(0x2088, (10, 10))
    b.velocity_mode()
    b.run(2.0)
    assert b.send(frame("zlac-modbus-2.1-ex-send")) == frame("zlac-modbus-2.1-ex-recv")


@pytest.mark.parametrize("seq_id", sorted(zlac_sequences()) or ["none"])
def test_replay_manual_sequences(seq_id: str) -> None:
    seqs = zlac_sequences()
    if not seqs:
        pytest.skip("vectors.json not available")
    seq = seqs[seq_id]
    torque = "3.4" in seq_id
    b = Bench(damping=2.0) if torque else Bench()  # torque mode: a viscous load keeps speeds bounded
    for sensor in b.emu.sensors:  # the manual's example values: exact readings
        sensor.model = IDEAL
    chain = [seq]
    while chain[0].get("prerequisite"):
        chain.insert(0, seqs[chain[0]["prerequisite"]])
    history: list[tuple[str, dict[str, int]]] = []
    for s in chain:
        for step in s["steps"]:
            reply = b.send(hexbytes(step["send_hex"]))
            assert reply == hexbytes(step["expect_hex"]), (s["id"], step["step"], reply.hex(" "))
            assert b.emu.state is not DriveState.FAULT
            b.run(7.0 if "3.2-" in s["id"] and "init" not in s["id"] else 4.5 if torque else 1.5)
            history.append((f'{s["id"]}#{step["step"]}', b.status()))
    last = history[-len(seq["steps"]):]
    if "init" in seq_id:
        assert b.emu.state is DriveState.ENABLED
        assert all(v == 0 for v in last[-1][1].values())  # enabled, at rest
        return
    # every control sequence ends with a stop: power stage off, wheels free
    assert b.emu.state is DriveState.DISABLED and split_left_right(b.read("motor_state")) == (0, 0)
    assert b.tau == [0.0, 0.0]
    moved = [s for s in SIDES if s in seq_id] or list(SIDES)  # "sync" moves both
    still = [s for s in SIDES if s not in moved]
    if "3.1-" in seq_id:  # velocity: +100 then -100 r/min (0.1 r/min units)
        for side in moved:
            assert last[0][1][f"actual_velocity_{side}"] == pytest.approx(1000, rel=0.03)
            assert last[1][1][f"actual_velocity_{side}"] == pytest.approx(-1000, rel=0.03)
        for side in still:
            assert last[1][1][f"actual_velocity_{side}"] == 0
    elif "3.2-" in seq_id:  # relative position: +20480 then -20480 counts, back to 0
        for side in moved:
            assert last[1][1][f"actual_motor_position_{side}"] == pytest.approx(20480, abs=3)
            assert last[3][1][f"actual_motor_position_{side}"] == pytest.approx(0, abs=3)
        for side in still:
            assert last[3][1][f"actual_motor_position_{side}"] == 0
    else:  # torque: +2000 mA at 500 mA/s reached after 4 s, then towards -2000 mA (8 s for the 4 A swing)
        for side in moved:
            assert last[0][1][f"actual_torque_{side}"] == 20  # 0.1 A
            assert last[0][1][f"actual_velocity_{side}"] > 0
            assert last[1][1][f"actual_torque_{side}"] == pytest.approx(-2, abs=1)  # 2 A - 4.5 s * 0.5 A/s
        for side in still:
            assert last[0][1][f"actual_torque_{side}"] == 0


# --------------------------------------------------------------------------- velocity mode


@pytest.mark.parametrize("target", [100, 200, -150])
def test_acceleration_time_is_the_time_to_reach_the_target(target: int) -> None:
    """0x2080: 500 ms from standstill to ANY target (100, 200 or -150 r/min), linear."""
    b = Bench()
    b.velocity_mode(accel_ms=500)
    t0 = b.t
    b.write_words(0x2088, (target, target))
    b.run(1.5)
    v = target * RPM
    T = 0.5
    for frac in (0.1, 0.5, 0.9):
        assert crossing(b.trace, 1, frac * v, t0) == pytest.approx(frac * T, abs=0.05 * T)
    assert crossing(b.trace, 1, 0.99 * v, t0) == pytest.approx(T, rel=0.05)
    assert crossing(b.trace, 2, 0.99 * v, t0) == pytest.approx(T, rel=0.05)
    assert b.status()["actual_velocity_left"] == pytest.approx(10 * target, rel=0.03)


def test_acceleration_time_register_changes_the_ramp() -> None:
    b = Bench()
    b.velocity_mode(accel_ms=1200)
    t0 = b.t
    b.write("target_velocity_left", 100)
    b.run(2.0)
    assert crossing(b.trace, 1, 0.5 * 100 * RPM, t0) == pytest.approx(0.6, rel=0.05)
    assert crossing(b.trace, 1, 0.99 * 100 * RPM, t0) == pytest.approx(1.2, rel=0.05)


def test_fixed_slope_alternative_semantics() -> None:
    """``ramp_reference_rpm``: the ramp time is the time for 0 -> that speed (slope, not duration)."""
    b = Bench(ramp_reference_rpm=1000)
    b.velocity_mode(accel_ms=500)
    t0 = b.t
    b.write_words(0x2088, (100, 200))
    b.run(0.048)
    assert b.emu.left.v_ref < 100 * RPM
    b.run(0.004)  # 1000 r/min per 500 ms: 100 r/min after 50 ms, 200 r/min after 100 ms
    assert b.emu.left.v_ref == pytest.approx(100 * RPM) and b.emu.right.v_ref < 200 * RPM
    b.run(0.05)
    assert b.emu.right.v_ref == pytest.approx(200 * RPM)
    b.run(0.5)
    assert crossing(b.trace, 1, 0.5 * 100 * RPM, t0) < 0.05  # the wheel follows (loop lag ~10 ms)
    assert b.rpm(1) == pytest.approx(200, rel=0.03)


def test_deceleration_time_and_reversal() -> None:
    b = Bench()
    b.velocity_mode(accel_ms=500, decel_ms=1000)
    b.write_words(0x2088, (100, 100))
    b.run(1.5)
    t0 = b.t
    b.write_words(0x2088, (0, 0))  # 100 -> 0 in the deceleration time
    b.run(1.5)
    levels = [(r[0] - t0, r[1]) for r in b.trace if r[0] > t0]
    t_half = next(t for t, v in levels if v <= 50 * RPM)
    t_stop = next(t for t, v in levels if v <= 1 * RPM)
    assert t_half == pytest.approx(0.5, rel=0.05) and t_stop == pytest.approx(0.99, rel=0.05)
    # reversal +100 -> -100: decelerate to 0 in 1000 ms, then accelerate to -100 in 500 ms
    b.write_words(0x2088, (100, 100))
    b.run(1.5)
    t0 = b.t
    b.write("target_velocity_left", -100)
    b.run(2.5)
    assert crossing(b.trace, 1, -0.01 * RPM, t0) == pytest.approx(1.0, rel=0.05)
    assert crossing(b.trace, 1, -99 * RPM, t0) == pytest.approx(1.5, rel=0.05)
    assert b.rpm(1) == pytest.approx(100, rel=0.03)  # right wheel untouched


def test_rewriting_the_same_target_does_not_restart_the_ramp() -> None:
    """A host that re-sends its set-point every cycle still gets the 500 ms ramp."""
    b = Bench()
    b.velocity_mode()
    t0 = b.t
    for _ in range(30):
        b.write("target_velocity_left", 100)
        b.run(0.02)
    assert crossing(b.trace, 1, 0.99 * 100 * RPM, t0) == pytest.approx(0.5, rel=0.05)


@pytest.mark.parametrize("rpm", [100, -100, 30, 200])
def test_steady_speed_within_3_percent(rpm: int) -> None:
    b = Bench(coulomb=0.5)  # more friction than the profile's estimate
    for sensor in b.emu.sensors:  # the loop's own speed: exact readings (the estimate steps by 0.29 r/min)
        sensor.model = IDEAL
    b.velocity_mode()
    b.write_words(0x2088, (rpm, rpm))
    b.run(2.0)
    speeds = [(r[1] / RPM, r[2] / RPM) for r in b.trace[-500:]]
    for left, right in speeds:
        assert left == pytest.approx(rpm, rel=0.03) and right == pytest.approx(rpm, rel=0.03)
    st = b.status()
    assert st["actual_velocity_left"] == pytest.approx(10 * rpm, rel=0.03)
    assert st["actual_velocity_right"] == pytest.approx(10 * rpm, rel=0.03)
    # steady current carries friction only (0.1 A units, sign of the motion)
    expected = (0.5 + PROFILE.viscous_friction * abs(rpm) * RPM) / PROFILE.torque_constant
    assert st["actual_torque_left"] == pytest.approx(math.copysign(10 * expected, rpm), abs=1)
    # position counts follow the integral of the speed (the encoder was sampled one substep ago)
    assert st["actual_motor_position_left"] == pytest.approx(b.counts(0), abs=abs(b.qd[0]) * DT * CPR / 6.28 + 1)


def test_sync_fc16_sets_both_wheels_single_write_sets_one() -> None:
    b = Bench()
    b.velocity_mode()
    assert b.write("target_velocity_right", 60) == mb.encode(mb.WriteSingleRegisterReply(1, 0x2089, 60))
    b.run(1.5)
    assert b.rpm(0) == pytest.approx(0, abs=0.01) and b.rpm(1) == pytest.approx(60, rel=0.03)
    reply = b.write_words(0x2088, (-80, 120))
    assert reply == mb.encode(mb.WriteMultipleRegistersReply(1, 0x2088, 2))
    b.run(1.5)
    assert b.rpm(0) == pytest.approx(-80, rel=0.03) and b.rpm(1) == pytest.approx(120, rel=0.03)
    assert (b.read("target_velocity_left"), b.read("target_velocity_right")) == (-80, 120)


def test_maximum_motor_speed_caps_the_target_and_back_emf_caps_the_motor() -> None:
    b = Bench()
    b.velocity_mode()
    b.write("maximum_motor_speed", 50)
    b.write_words(0x2088, (100, 100))
    b.run(1.5)
    assert b.rpm(0) == pytest.approx(50, rel=0.03)
    b.write("maximum_motor_speed", 1000)
    t0 = b.t
    b.write_words(0x2088, (300, 300))  # above the 24 V no-load speed (262 r/min)
    b.run(3.0, until=lambda bb: bb.emu.state is DriveState.FAULT)
    top = max(r[1] for r in b.trace if r[0] > t0) / RPM
    assert 250 < top < 262
    # the speed command runs away from the wheel: one turn of lag is a velocity following error
    assert b.read("error_code_left") & Fault.VELOCITY_FOLLOWING_ERROR


def test_out_of_range_and_read_only_writes_are_refused() -> None:
    b = Bench()
    assert b.exception_code(b.request(mb.WriteSingleRegister(1, 0x2088, 3001))) == 0x03
    assert b.exception_code(b.request(mb.WriteSingleRegister(1, 0x20AB, 5))) == 0x02
    assert b.exception_code(b.request(mb.WriteSingleRegister(1, 0x2005, 2))) == 0x03
    # FC16 with one bad value changes nothing
    assert b.exception_code(b.write_words(0x2088, (100, 4000))) == 0x03
    assert b.read("target_velocity_left") == 0
    # absolute mode: target beyond +-0x3FFFFFFF (line 436) is refused; relative mode allows it
    b.write("control_mode", 1)
    assert b.exception_code(b.write("target_position_left", 0x40000000)) is None
    b.write("control_mode", 2)
    assert b.exception_code(b.write("target_position_left", 0x40000000)) == 0x03
    assert b.exception_code(b.write("target_position_left", -0x3FFFFFFF)) is None


# ----------------------------------------------------------------------------- torque mode


def test_torque_slope_and_torque_at_the_wheel() -> None:
    b = Bench(damping=2.0)
    b.write("control_mode", 4)
    b.write("torque_rate_left", 1000)  # 1000 mA/s
    b.write("torque_rate_right", 0)  # 0: step
    b.write("control_word", 0x08)
    t0 = b.t
    b.write_words(0x2090, (2000, 1500))
    b.run(3.0)
    taus = [(r[0] - t0, r[3], r[4]) for r in b.trace]
    kt = PROFILE.torque_constant
    for t, tl, tr in taus:
        assert tl == pytest.approx(min(2.0, 1.0 * t) * kt, abs=1.1e-3 * kt)  # 1 A/s, capped at 2 A
        assert tr == pytest.approx(1.5 * kt)
    st = b.status()
    assert (st["actual_torque_left"], st["actual_torque_right"]) == (20, 15)
    # steady speed = torque / load damping (minus coulomb)
    assert b.qd[0] == pytest.approx((2.0 * kt - PROFILE.coulomb_friction) / 2.0, rel=0.02)
    # a new target ramps from where the current is
    t0 = b.t
    b.write("target_torque_left", -1000)
    b.run(0.5)
    assert b.tau[0] == pytest.approx(1.5 * kt, abs=2e-3)
    b.run(2.5)
    assert b.tau[0] == pytest.approx(-1.0 * kt)


def test_torque_mode_speed_is_capped_at_maximum_motor_speed() -> None:
    b = Bench(damping=0.0, coulomb=0.0)
    b.write("maximum_motor_speed", 60)
    b.write("control_mode", 4)
    b.write("torque_rate_left", 0)
    b.write("control_word", 0x08)
    b.write("target_torque_left", 5000)
    b.run(3.0)
    assert b.rpm(0) == pytest.approx(60, rel=0.03)


def test_control_mode_is_shared_by_both_motors() -> None:
    b = Bench(damping=2.0)
    b.velocity_mode()
    b.write_words(0x2088, (50, 50))
    b.run(1.0)
    b.write("torque_rate_left", 0)
    b.write("torque_rate_right", 0)
    b.write("control_mode", 4)  # both wheels leave velocity control
    b.write_words(0x2090, (1000, -1000))
    b.run(2.0)
    assert b.tau[0] == pytest.approx(0.8) and b.tau[1] == pytest.approx(-0.8)
    b.write("target_velocity_left", 100)  # stored, not executed in torque mode
    b.run(0.5)
    assert b.tau[0] == pytest.approx(0.8)
    assert b.read("target_velocity_left") == 100
    b.write("control_mode", 3)  # back to velocity: both follow the velocity targets
    b.run(1.5)
    assert b.rpm(0) == pytest.approx(100, rel=0.03) and b.rpm(1) == pytest.approx(50, rel=0.03)


# --------------------------------------------------------------------------- position modes


def test_relative_moves_async_and_ignored_starts() -> None:
    b = Bench()
    b.position_mode(mode=1, sync=0, speed=60)
    b.write("target_position_left", 8192)
    b.write("target_position_right", 4096)
    b.write("control_word", 0x10)  # START_SYNC in asynchronous control: nothing
    b.run(0.5)
    assert b.emu.ignored and "START_SYNC" in b.emu.ignored[-1][1]
    assert abs(b.counts(0)) < 2
    b.write("control_word", 0x11)  # left only
    b.run(3.0)
    assert b.read("actual_motor_position_left") == pytest.approx(8192, abs=2)
    assert abs(b.read("actual_motor_position_right")) < 2
    b.write("control_word", 0x12)
    b.run(3.0)
    assert b.read("actual_motor_position_right") == pytest.approx(4096, abs=2)
    b.write("control_word", 0x11)  # relative: again 8192 from the previous end point
    b.run(3.0)
    assert b.read("actual_motor_position_left") == pytest.approx(16384, abs=2)


def test_relative_move_profile_timing() -> None:
    b = Bench()
    b.position_mode(mode=1, sync=0, speed=60)
    b.write("target_position_left", 8192)
    t0 = b.t
    b.write("control_word", 0x11)
    b.run(3.5, until=lambda bb: not bb.emu.left.moving)
    # 2 turns at 1 turn/s with 0.5 s linear ramps: 2 s + 0.5 s
    assert b.t - t0 == pytest.approx(2.5, abs=0.01)
    peak = max(abs(r[1]) for r in b.trace)
    assert peak == pytest.approx(60 * RPM, rel=0.03)


def test_synchronous_start_and_absolute_mode() -> None:
    b = Bench()
    b.position_mode(mode=2, sync=1, speed=100)
    b.write_words(0x208A, (0, 4096, 0xFFFF, (-2048) & 0xFFFF))
    b.write("control_word", 0x11)  # single start in synchronous control: nothing
    b.run(0.3)
    assert "synchronous" in b.emu.ignored[-1][1]
    b.write("control_word", 0x10)
    b.run(2.0)
    assert b.read("actual_motor_position_left") == pytest.approx(4096, abs=2)
    assert b.read("actual_motor_position_right") == pytest.approx(-2048, abs=2)
    b.write("control_word", 0x10)  # absolute: the same target again moves nothing
    b.run(1.0)
    assert b.read("actual_motor_position_left") == pytest.approx(4096, abs=2)


def test_start_while_disabled_or_in_velocity_mode_does_nothing() -> None:
    b = Bench()
    b.write("control_mode", 1)
    b.write("target_position_left", 4096)
    b.write("control_word", 0x11)
    b.run(0.5)
    assert "disabled" in b.emu.ignored[-1][1] and b.counts(0) == 0
    b.velocity_mode()
    b.write("control_word", 0x11)
    b.run(0.5)
    assert "position modes" in b.emu.ignored[-1][1] and abs(b.counts(0)) < 1


# ---------------------------------------------------------------------------- stop commands


def test_stop_switches_the_power_stage_off() -> None:
    b = Bench(coulomb=0.0)
    b.velocity_mode()
    b.write_words(0x2088, (100, 100))
    b.run(1.5)
    assert split_left_right(b.read("motor_state")) == (1, 1)
    assert b.write("control_word", 0x07) == hexbytes("01 06 20 0E 00 07 A2 0B")
    b.run(1.0)
    assert b.tau == [0.0, 0.0]
    assert b.rpm(0) > 90  # coasting (viscous friction only)
    assert split_left_right(b.read("motor_state")) == (0, 0)
    assert b.emu.state is DriveState.DISABLED


@pytest.mark.parametrize(
    "option,register,ms",
    [(5, "deceleration_time", 800), (6, "deceleration_time_of_quick_stop", 200), (7, None, 0)],
)
def test_quick_stop_follows_0x2011(option: int, register: str | None, ms: int) -> None:
    b = Bench()
    b.velocity_mode(decel_ms=800)
    for side in SIDES:
        b.write(f"deceleration_time_of_quick_stop_{side}", 200)
    b.write("quick_stop_control", option)
    b.write_words(0x2088, (100, -100))
    b.run(1.5)
    t0 = b.t
    assert b.write("control_word", 0x05) == hexbytes("01 06 20 0E 00 05 23 CA")
    b.run(1.5)
    t_stop = next(r[0] - t0 for r in b.trace if r[0] > t0 and abs(r[1]) < 1 * RPM)
    if register:
        assert t_stop == pytest.approx(ms * 1e-3 * 0.99, rel=0.05)
    else:  # without deceleration time: braking at the current limit (24 N*m on 0.14 kg*m^2)
        assert t_stop < 0.1
    assert abs(b.rpm(0)) < 0.5 and abs(b.rpm(1)) < 0.5
    # stays energised (holds zero speed); set-points are stored but not executed
    assert b.emu.state is DriveState.QUICK_STOP and split_left_right(b.read("motor_state")) == (1, 1)
    b.write_words(0x2088, (50, 50))
    b.run(0.5)
    assert abs(b.rpm(0)) < 0.5
    b.write("control_word", 0x08)  # enable resumes with the present targets
    b.run(1.0)
    assert b.rpm(0) == pytest.approx(50, rel=0.03) and b.rpm(1) == pytest.approx(50, rel=0.03)


# -------------------------------------------------------------------------------- faults


def test_overload_fault_after_the_overload_time() -> None:
    b = Bench()
    b.velocity_mode()
    b.write("overload_protection_time_left", 100)  # 1.0 s
    b.write_words(0x2088, (60, 60))
    b.run(1.5)
    t0 = b.t
    b.load[0] = -16.0  # 16 N*m against the left wheel: ~20 A > rated 15 A, < max 30 A
    b.run(3.0, until=lambda bb: bb.emu.state is DriveState.FAULT)
    assert b.emu.state is DriveState.FAULT
    assert b.t - t0 == pytest.approx(1.0, abs=0.05)
    st = b.status()
    assert st["error_code_left"] == Fault.OVER_LOAD and st["error_code_right"] == 0
    b.run(0.1)
    assert b.tau == [0.0, 0.0]  # both motors off
    assert split_left_right(b.read("motor_state")) == (0, 0)


def test_current_stays_within_rated_without_fault() -> None:
    b = Bench()
    b.velocity_mode()
    b.write_words(0x2088, (60, 60))
    b.run(1.5)
    b.load[0] = -11.0  # 11 N*m: ~14 A, below the rated 15 A
    b.run(5.0)
    assert b.emu.state is DriveState.ENABLED
    assert b.status()["actual_torque_left"] == pytest.approx(140, abs=4)


def test_position_following_error() -> None:
    b = Bench()
    b.position_mode(mode=1, sync=0, speed=100)
    b.blocked[0] = True  # the left wheel is against a wall
    b.write("target_position_left", 40960)
    t0 = b.t
    b.write("control_word", 0x11)
    b.run(5.0, until=lambda bb: bb.emu.state is DriveState.FAULT)
    assert b.read("error_code_left") == Fault.POSITION_FOLLOWING_ERROR
    assert b.read("error_code_right") == 0
    # threshold 409 x 10 counts; the profile gets there after ~0.5 s ramp + ~0.35 s cruise
    lag = 4090 / CPR * 2 * math.pi
    a = 100 * RPM / 0.5
    t_expected = 0.5 + (lag - 0.5 * a * 0.5**2) / (100 * RPM)
    assert b.t - t0 == pytest.approx(t_expected, abs=0.05)


def test_velocity_following_error_on_a_blocked_wheel() -> None:
    b = Bench()
    b.velocity_mode(accel_ms=0)
    b.blocked[1] = True
    t0 = b.t
    b.write_words(0x2088, (100, 100))
    b.run(3.0, until=lambda bb: bb.emu.state is DriveState.FAULT)
    assert b.read("error_code_right") == Fault.VELOCITY_FOLLOWING_ERROR
    assert b.read("error_code_left") == 0
    assert b.t - t0 == pytest.approx((4090 / CPR) / (100 / 60), abs=0.02)  # 1 turn of lag at 100 r/min


def test_clear_fault_then_enable() -> None:
    b = Bench()
    b.velocity_mode(accel_ms=0)
    b.blocked[0] = True
    b.write_words(0x2088, (100, 100))
    b.run(2.0)
    assert b.emu.state is DriveState.FAULT
    b.blocked[0] = False
    assert b.write("control_word", 0x08) == hexbytes("01 06 20 0E 00 08 E2 0F")  # echoed ...
    b.run(0.5)
    assert b.emu.state is DriveState.FAULT and b.tau == [0.0, 0.0]  # ... but ignored while faulted
    assert b.write("control_word", 0x06) == hexbytes("01 06 20 0E 00 06 63 CB")
    st = b.status()
    assert st["error_code_left"] == 0 and st["error_code_right"] == 0
    assert b.state() is DriveState.DISABLED
    b.write("control_word", 0x08)
    b.run(1.5)
    assert b.rpm(0) == pytest.approx(100, rel=0.03) and b.rpm(1) == pytest.approx(100, rel=0.03)


def test_over_temperature_fault_and_it_returns_while_hot() -> None:
    b = Bench(damping=3.0)
    b.write("control_mode", 4)
    for side in SIDES:
        b.write(f"torque_rate_{side}", 0)
        b.write(f"over_temperature_threshold_{side}", 270)  # 27.0 degC, ambient 25
    b.write("control_word", 0x08)
    b.write("target_torque_left", 12000)  # 12 A: below the rated 15 A, twice the motor's 6 A
    b.run(20.0, until=lambda bb: bb.emu.state is DriveState.FAULT)
    assert b.read("error_code_left") == Fault.MOTOR_OVER_TEMPERATURE
    # +60 K * (12/6)^2 = 240 K final rise, tau 600 s: 2 K after ~5 s
    assert 4.0 < b.t < 6.5
    assert split_left_right(b.read("motor_temperature"))[0] == 27
    b.write("control_word", 0x06)
    b.run(0.01)
    assert b.read("error_code_left") == Fault.MOTOR_OVER_TEMPERATURE  # still hot


# ----------------------------------------------------------------------- offline watchdog


def test_offline_watchdog_stops_the_motors() -> None:
    b = Bench()
    b.write("communication_offline_time", 200)
    b.velocity_mode()
    b.write_words(0x2088, (100, 100))
    b.run(1.0)
    assert b.read("software_connected_status") == 1
    b.poll = 0.0  # the host goes silent
    t0 = b.t
    b.run(1.0)
    # nothing for 200 ms -> quick stop per 0x2011 (6: quick-stop deceleration 10 ms)
    t_trip = next(r[0] - t0 for r in b.trace if r[0] > t0 and r[1] < 99 * RPM)
    assert t_trip == pytest.approx(0.2, abs=0.01)
    assert abs(b.rpm(0)) < 0.5 and abs(b.rpm(1)) < 0.5
    assert b.emu.offline and b.emu.state is DriveState.QUICK_STOP
    b.poll = 0.05  # the host is back: the flag stays until enable, no fault bit, no restart
    st = b.status()
    assert st["error_code_left"] == 0 and st["error_code_right"] == 0
    assert b.read("software_connected_status") == 0
    b.run(1.0)
    assert abs(b.rpm(0)) < 0.5
    b.write("control_word", 0x08)
    assert b.read("software_connected_status") == 1 and not b.emu.offline
    b.run(1.5)
    assert b.rpm(0) == pytest.approx(100, rel=0.03)


def test_offline_watchdog_default_and_disabled() -> None:
    b = Bench()
    b.velocity_mode()
    b.write_words(0x2088, (100, 100))
    b.run(1.0)
    b.poll = 0.0
    t0 = b.t
    b.run(1.5)
    t_trip = next(r[0] - t0 for r in b.trace if r[0] > t0 and r[1] < 99 * RPM)
    assert t_trip == pytest.approx(1.0, abs=0.01)  # default 0x2000 = 1000 ms
    c = Bench()
    c.write("communication_offline_time", 0)  # 0: no watchdog
    c.velocity_mode()
    c.write_words(0x2088, (100, 100))
    c.poll = 0.0
    c.run(3.0)
    assert c.rpm(0) == pytest.approx(100, rel=0.03) and not c.emu.offline


def test_watchdog_only_after_a_first_frame_and_only_when_energised() -> None:
    b = Bench()
    b.poll = 0.0
    b.run(2.0)  # disabled and silent: nothing happens
    assert b.emu.state is DriveState.DISABLED and not b.emu.offline


# --------------------------------------------------------------- zero point / feedback position


def test_clear_feedback_position_and_reset_zero_point() -> None:
    b = Bench()
    b.velocity_mode()
    b.write_words(0x2088, (30, -45))
    b.run(2.0)
    b.write_words(0x2088, (0, 0))
    b.run(1.0)
    st = b.status()
    assert st["actual_motor_position_left"] > 1000 and st["actual_motor_position_right"] < -1000
    q_before = list(b.q)
    # 0x2006 = 1: left zero point only; reads back 0 (not saved)
    reply = b.write("in_absolute_position_control_reset_the_zero_point", 1)
    assert reply == mb.encode(mb.WriteSingleRegisterReply(1, 0x2006, 1))
    st = b.status()
    assert st["actual_motor_position_left"] == 0 and st["actual_motor_position_right"] < -1000
    assert b.read("in_absolute_position_control_reset_the_zero_point") == 0
    b.write("in_absolute_position_control_reset_the_zero_point", 2)
    assert b.status()["actual_motor_position_right"] == 0
    b.run(0.5)
    assert b.q == pytest.approx(q_before, abs=1e-3)  # nothing moved
    # 0x2005 = 1 clears both feedback positions
    b.write_words(0x2088, (20, 20))
    b.run(1.0)
    b.write("clear_feedback_position", 1)
    st = b.status()
    assert abs(st["actual_motor_position_left"]) <= 1 and abs(st["actual_motor_position_right"]) <= 1
    assert b.read("clear_feedback_position") == 0
    # absolute targets are counted from the new zero
    b.write_words(0x2088, (0, 0))
    b.run(1.0)
    b.write("in_absolute_position_control_reset_the_zero_point", 3)
    q0 = list(b.q)
    b.write("control_word", 0x07)
    b.position_mode(mode=2, sync=1, speed=60)
    b.write_words(0x208A, (0, 2048, 0, 2048))
    b.write("control_word", 0x10)
    b.run(2.0)
    assert b.q[0] - q0[0] == pytest.approx(math.pi, abs=2e-3)
    assert b.q[1] - q0[1] == pytest.approx(math.pi, abs=2e-3)


# ------------------------------------------------------------------ power cycle / persistence


def test_power_cycle_keeps_stored_settings_only() -> None:
    b = Bench()
    b.write("acceleration_time_left", 250)
    b.write("rs485_node_id", 7)
    b.write("whether_store_rw_register_to_eeprom", 1)
    assert b.read("whether_store_rw_register_to_eeprom") == 0
    b.write("acceleration_time_right", 900)  # not stored
    b.velocity_mode(accel_ms=250)
    b.write_words(0x2088, (50, 50))
    b.run(2.0)
    b.write_words(0x2088, (0, 0))
    b.run(1.0)
    assert b.status()["actual_motor_position_left"] > 1000
    b.emu.power_cycle()
    assert b.front.address == 7 and b.emu.state is DriveState.DISABLED
    bus = ModbusDeviceBus([b.front])
    reply = bus.receive(mb.encode(mb.ReadHoldingRegisters(7, 0x2080, 2)))
    assert reply == mb.encode(mb.ReadRegistersReply(7, 3, (250, 500)))
    b.bus, b.address = bus, 7
    assert b.read("target_velocity_left") == 0  # set-points are not stored
    assert b.read("control_mode") == 0
    b.run(0.5)
    assert b.status()["actual_motor_position_left"] == 0  # incremental counter restarts at 0
    # factory restore forgets the stored settings
    b.write("register_parameter_settings", 1)
    assert b.read("acceleration_time_left") == 500 and b.read("register_parameter_settings") == 0


def test_driver_state_enables_at_power_on() -> None:
    b = Bench()
    b.write("control_mode", 3)
    b.write("driver_state", 1)
    b.write("whether_store_rw_register_to_eeprom", 1)
    b.run(0.5)
    b.emu.power_cycle()
    b.n = 0  # the world's clock restarts with the power cycle (World.reset)
    assert b.emu.state is DriveState.ENABLED
    b.write_words(0x2088, (40, 40))
    b.run(1.5)
    assert b.rpm(0) == pytest.approx(40, rel=0.03)


def test_encoder_lines_set_the_counts_per_turn() -> None:
    b = Bench()
    b.write("encoder_line_left", 4096)  # a 4096-line motor: 16384 counts/rev
    b.position_mode(mode=1, sync=0, speed=60)
    b.write("target_position_left", 16384)
    b.write("control_word", 0x11)
    b.run(3.0)
    assert b.q[0] == pytest.approx(2 * math.pi, abs=1e-3)
    assert b.read("actual_motor_position_left") == pytest.approx(16384, abs=4)


def test_free_wheel_with_default_tuning_is_stable() -> None:
    """A wheel in the air (only the rotor inertia) with gains tuned for the vehicle: no oscillation."""
    b = Bench(inertia=PROFILE.armature)
    b.velocity_mode()
    b.write_words(0x2088, (100, 100))
    b.run(2.0)
    tail = [r[1] / RPM for r in b.trace[-1000:]]
    assert max(tail) == pytest.approx(100, rel=0.03) and min(tail) == pytest.approx(100, rel=0.03)
    assert max(r[1] / RPM for r in b.trace) < 110


def test_gains_assume_the_wheel_plus_the_vehicle_share() -> None:
    """inertia_left/right is the wheel's own joint inertia; the drive's tuning adds the vehicle."""
    emu = ZlacFirmware(PROFILE, 1, inertia_left=0.02)
    assert emu.left.inertia == pytest.approx(0.02 + PROFILE.load_inertia)
    assert emu.right.inertia == pytest.approx(PROFILE.tuning_inertia)
    # a wheel in the air on a bench: a profile without vehicle share, tight tracking
    bench = PROFILE.with_overrides(load_inertia=0.0)
    b = Bench(inertia=PROFILE.armature, profile=bench)
    assert b.emu.left.inertia == pytest.approx(PROFILE.armature)
    b.velocity_mode()
    t0 = b.t
    b.write_words(0x2088, (100, 100))
    b.run(1.0)
    assert crossing(b.trace, 1, 0.99 * 100 * RPM, t0) == pytest.approx(0.5, rel=0.05)
    assert max(r[1] for r in b.trace) / RPM < 102


def test_place_sets_the_start_state() -> None:
    emu = ZlacFirmware(PROFILE, 1)
    bus = ModbusDeviceBus([front(emu)])
    emu.left.place(1.0)  # before the first step (power-on): the counter reads 0 here
    emu.left.step(0.001, DT, 1.0, 0.0)
    reply = bus.receive(mb.encode(mb.ReadHoldingRegisters(1, 0x20A7, 2)))
    assert reply == mb.encode(mb.ReadRegistersReply(1, 3, (0, 0)))
    emu.left.place(1.0 + math.pi)  # turned half a turn by hand later: the counter follows
    emu.left.step(0.002, DT, 1.0 + math.pi, 0.0)
    reply = bus.receive(mb.encode(mb.ReadHoldingRegisters(1, 0x20A7, 2)))
    assert reply == mb.encode(mb.ReadRegistersReply(1, 3, (0, 2048)))
    emu.power_cycle()
    emu.left.place(5.0)
    emu.left.step(0.001, DT, 5.0, 0.0)  # the world's clock restarts at a reset
    assert emu.left.counts() == 0


def test_channel_accessor_and_packed_status() -> None:
    b = Bench()
    assert b.emu.channel("left") is b.emu.left and b.emu.channel("right") is b.emu.right
    with pytest.raises(KeyError):
        b.emu.channel("middle")
    b.velocity_mode()
    b.write("target_velocity_left", 20)
    halls = set()
    for _ in range(40):
        b.run(0.05)
        halls.add(split_left_right(b.read("hall_state"))[0])
    assert halls == {1, 2, 3, 4, 5, 6}  # 15 pole pairs: 6 sectors per 24 degrees
    assert split_left_right(b.read("motor_state")) == (1, 1)


def test_both_channels_step_with_one_clock() -> None:
    b = Bench()
    b.velocity_mode()
    b.write_words(0x2088, (100, 100))
    tl, tr = b.emu.step_both(0.001, DT, 0.0, 0.0, 0.0, 0.0)
    assert tl == pytest.approx(tr) and tl > 0


# ------------------------------------------------------------------------- MuJoCo model


def test_diffdrive_model_drives_straight_and_turns_in_place() -> None:
    mujoco = pytest.importorskip("mujoco")
    import numpy as np

    spec = mujoco.MjSpec.from_file(str(ROOT / "models" / "zlac_diffdrive.xml"))
    m0 = spec.compile()
    assert m0.nu == 0, "actuators come from the device profile, not the XML"
    assert [m0.joint(i).name for i in range(m0.njnt)] == ["chassis", "left_wheel", "right_wheel"]
    assert 20.0 <= float(np.sum(m0.body_mass)) <= 30.0
    for name in ("left_wheel", "right_wheel"):
        jnt = spec.joint(name)
        jnt.armature = PROFILE.armature
        damping = jnt.damping
        jnt.damping = [PROFILE.viscous_friction] + [0.0] * (len(damping) - 1) if hasattr(damping, "__len__") \
            else PROFILE.viscous_friction
        jnt.frictionloss = PROFILE.coulomb_friction
        act = spec.add_actuator()
        act.name, act.target, act.trntype = f"{name}_motor", name, mujoco.mjtTrn.mjTRN_JOINT
        act.gainprm[0] = 1.0
        act.ctrllimited = 1
        act.ctrlrange = [-PROFILE.max_torque, PROFILE.max_torque]
    m = spec.compile()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)

    def dof_inertia(dof: int) -> float:  # what World passes: the joint-space diagonal incl. armature
        unit, out = np.zeros(m.nv), np.zeros(m.nv)
        unit[dof] = 1.0
        mujoco.mj_mulM(m, d, out, unit)
        return float(out[dof])

    dofs = {n: int(m.jnt_dofadr[m.joint(n).id]) for n in ("left_wheel", "right_wheel")}
    assert dof_inertia(dofs["left_wheel"]) == pytest.approx(PROFILE.armature + 2e-4)
    emu = ZlacFirmware(PROFILE, 1, inertia_left=dof_inertia(dofs["left_wheel"]),
                       inertia_right=dof_inertia(dofs["right_wheel"]))
    bus = ModbusDeviceBus([front(emu)])
    bind = [(ch, int(m.jnt_qposadr[m.joint(n).id]), dofs[n], m.actuator(f"{n}_motor").id)
            for ch, n in ((emu.left, "left_wheel"), (emu.right, "right_wheel"))]
    for ch, qa, _da, _aid in bind:
        ch.place(float(d.qpos[qa]))
    site = m.site("base").id
    steps = [0]

    def run(seconds: float) -> None:
        for _ in range(round(seconds / m.opt.timestep)):
            steps[0] += 1
            t = steps[0] * m.opt.timestep
            for ch, qa, da, aid in bind:
                d.ctrl[aid] = ch.step(t, m.opt.timestep, float(d.qpos[qa]), float(d.qvel[da]))
            mujoco.mj_step(m, d)
            if steps[0] % 50 == 0:
                bus.receive(mb.encode(mb.ReadHoldingRegisters(1, STATUS_BLOCK_START, STATUS_BLOCK_WORDS)))

    def pose() -> tuple[Any, float]:
        rot = d.site_xmat[site].reshape(3, 3)
        return d.site_xpos[site].copy(), math.atan2(rot[1, 0], rot[0, 0])

    def send(req: mb.Request) -> None:
        assert bus.receive(mb.encode(req))[1] < 0x80

    run(0.5)  # settle on the floor
    send(mb.WriteSingleRegister(1, 0x200D, 3))
    send(mb.WriteSingleRegister(1, 0x200E, 0x08))
    send(mb.WriteMultipleRegisters(1, 0x2088, (100, 100)))
    run(1.0)
    p1, yaw1 = pose()
    run(2.0)
    p2, yaw2 = pose()
    v = (p2 - p1) / 2.0
    assert v[0] == pytest.approx(PROFILE.wheel_speed(100), rel=0.03)  # forward, no slip
    assert abs(v[1]) < 0.01 and abs(yaw2) < 0.01 and abs(yaw2 - yaw1) < 0.005  # straight
    send(mb.WriteMultipleRegisters(1, 0x2088, (0, 0)))
    run(1.5)
    send(mb.WriteMultipleRegisters(1, 0x2088, (100, (-100) & 0xFFFF)))
    run(1.0)
    pa, _ = pose()
    yaw_rate = float(d.qvel[5])
    run(2.0)
    pb, _ = pose()
    assert np.linalg.norm((pb - pa)[:2]) < 0.02  # in place
    track = 0.4
    assert yaw_rate == pytest.approx(-2 * PROFILE.wheel_speed(100) / track, rel=0.05)  # clockwise
    assert emu.state is DriveState.ENABLED
