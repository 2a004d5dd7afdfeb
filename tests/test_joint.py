"""Joint: SI units, limits and safety over the real eRob driver, link, codec and a scripted slave.

Joint -> ErobModbusDriver -> ModbusLink -> LoopbackTransport -> ModbusDeviceBus -> ModbusFront ->
scripted firmware. The firmware's ``write_log`` records every accepted write, so "nothing was sent"
is checkable.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pytest

from joints.clock import ManualClock
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.erob.profiles import DEFAULT_MODEL, profile
from joints.devices.erob.registers import (
    COUNTS_PER_REV,
    EROB_MODBUS,
    AchieveStatus,
    MotionStatus,
    OperationMode,
)
from joints.drivers.base import RawState, raw_state, slots_maker
from joints.drivers.erob_modbus import ErobModbusDriver
from joints.errors import (
    CommandError,
    ConfirmationRequired,
    DeviceFault,
    LimitError,
    MotionTimeout,
    RegisterError,
    StateError,
)
from joints.joint import Joint, JointState, Limits, Motion
from joints.link.modbus import ModbusLink
from joints.sim.firmware import Firmware
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.transports.loopback import LoopbackTransport

RAD = 2 * math.pi / COUNTS_PER_REV  # rad per count
KT = profile(DEFAULT_MODEL).torque_constant  # N*m per A at the output


def counts(rad: float) -> int:
    return round(rad / (2 * math.pi) * COUNTS_PER_REV)


class FakeErob(Firmware):
    """A parameter store that acts just enough like an eRob for the joint layer.

    "Enable the Motor" switches the achieving-position status between motor off and motor on;
    "Start Operating" makes it move for ``move_reads`` status reads, then report target reached;
    the stop commands end a motion at once. ``fault(code)`` latches an error code.
    """

    def __init__(self, address: int = 2, *, move_reads: int = 3) -> None:
        super().__init__(EROB_PARAMS)
        self.address = address
        self.move_reads = move_reads
        self._left = 0
        self.status_reads = 0

    def _standstill(self, achieve: AchieveStatus) -> None:
        self.set("motion_status", MotionStatus.STOP)
        self.set("status_of_achieving_position", achieve)
        self._left = 0

    def on_write(self, name: str, value: int) -> None:
        if name == "enable_the_motor":
            self._standstill(AchieveStatus.MOTOR_ON if value else AchieveStatus.MOTOR_OFF)
        elif name == "start_operating" and self.get("status_of_achieving_position") != AchieveStatus.MOTOR_OFF:
            self.set("motion_status", MotionStatus.MOVING)
            self.set("status_of_achieving_position", AchieveStatus.OPERATION)
            self._left = self.move_reads
        elif name in ("stop_operating", "emergency_stop") and self._left:
            self._standstill(AchieveStatus.MOTOR_ON)
        elif name == "clear_errors":
            self.set("error_code", 0)

    def on_read(self, names: Sequence[str]) -> None:
        if "motion_status" in names:
            self.status_reads += 1
            if self._left:
                self._left -= 1
                if not self._left:
                    self.set("actual_position", self.get("target_absolute_position"))
                    self._standstill(AchieveStatus.TARGET_REACHED)

    def fault(self, code: int) -> None:
        self.set("error_code", code)

    def writes(self, name: str) -> list[int]:
        return [v for n, v in self.write_log if n == name]

    def bus(self) -> ModbusDeviceBus:
        return ModbusDeviceBus([ModbusFront(self, EROB_MODBUS, self.address)])


@dataclass
class Bench:
    joint: Joint
    slave: FakeErob
    clock: ManualClock
    driver: ErobModbusDriver

    def sent(self) -> list[tuple[str, int]]:
        return list(self.slave.write_log)


def bench(*, limits: Limits | None = None, motion: Motion | None = None, offset: float = 0.0,
          direction: int = 1, enabled: bool = False, move_reads: int = 3) -> Bench:
    slave = FakeErob(2, move_reads=move_reads)
    clock = ManualClock()
    link = ModbusLink(LoopbackTransport(slave.bus()), clock=clock)
    driver = ErobModbusDriver(link, 2, clock=clock, name="shoulder")
    joint = Joint("shoulder", driver, clock=clock, limits=limits, motion=motion, offset=offset,
                  direction=direction)
    b = Bench(joint, slave, clock, driver)
    if enabled:
        joint.enable()
    return b


# --- SI conversions ---------------------------------------------------------------------------


def test_move_to_writes_counts_and_profile() -> None:
    b = bench(enabled=True, motion=Motion(velocity=0.5, acceleration=2.0, deceleration=3.0))
    b.joint.move_to(1.0)
    s = b.slave
    assert s.get("target_absolute_position") == round(1.0 / (2 * math.pi) * 524288) == 83443
    assert s.get("operation_mode") == OperationMode.POSITION
    assert s.get("profile_speed") == counts(0.5)
    assert s.get("profile_acceleration") == counts(2.0)
    assert s.get("profile_deceleration") == counts(3.0)
    assert s.writes("start_operating") == [1]
    # the target is written before the start command
    names = [n for n, _ in s.write_log]
    assert names.index("target_absolute_position") < names.index("start_operating")


def test_move_to_arguments_override_the_default_profile() -> None:
    b = bench(enabled=True)
    b.joint.move_to(-0.5, velocity=1.0, acceleration=4.0, deceleration=5.0)
    s = b.slave
    assert s.get("target_absolute_position") == counts(-0.5)
    assert (s.get("profile_speed"), s.get("profile_acceleration"), s.get("profile_deceleration")) == (
        counts(1.0), counts(4.0), counts(5.0))


def test_move_waits_500ms_after_enable_on_the_injected_clock() -> None:
    b = bench(enabled=True)
    assert b.clock.now() == 0.0
    b.joint.move_to(0.1)
    assert b.clock.now() == pytest.approx(0.5)


def test_set_velocity_writes_count_per_second() -> None:
    b = bench(enabled=True)
    b.joint.set_velocity(0.5)
    assert b.slave.get("operation_mode") == OperationMode.SPEED
    assert b.slave.get("target_speed") == counts(0.5) == 41722
    b.joint.set_velocity(-0.25)
    assert b.slave.get("target_speed") == counts(-0.25)


def test_set_torque_writes_milliamps() -> None:
    b = bench(enabled=True)
    b.joint.set_torque(2.0)
    assert b.slave.get("operation_mode") == OperationMode.TORQUE
    assert b.slave.get("target_current") == round(2.0 / KT * 1000)
    b.joint.set_torque(-1.0)
    assert b.slave.get("target_current") == round(-1.0 / KT * 1000)


def test_state_converts_to_si() -> None:
    b = bench(enabled=True)
    s = b.slave
    s.set("actual_position", 262144)
    s.set("current_speed", -524288)
    s.set("motor_current", 1500)
    s.set("part_of_power_temperature", 41)
    b.clock.advance(1.25)
    st = b.joint.state()
    assert isinstance(st, JointState)
    assert st.position == pytest.approx(math.pi)
    assert st.velocity == pytest.approx(-2 * math.pi)
    assert st.current == pytest.approx(1.5)
    assert st.torque == pytest.approx(1.5 * KT)
    assert st.temperature == 41.0
    assert st.enabled is True and st.moving is False and st.fault is None
    assert st.time == pytest.approx(b.clock.now())
    assert st.raw is not None and st.raw.position == 262144


def test_state_reports_disabled_drive() -> None:
    b = bench()
    assert b.joint.state().enabled is False
    assert b.joint.enabled is False


def test_direction_and_offset_are_applied_both_ways() -> None:
    b = bench(enabled=True, direction=-1, offset=0.5)
    b.joint.move_to(1.0)
    target = b.slave.get("target_absolute_position")
    assert target == round((1.0 - 0.5) * -1 / RAD)
    b.slave.set("actual_position", target)
    b.slave.set("current_speed", 1000)
    b.slave.set("motor_current", 200)
    st = b.joint.state()
    assert st.position == pytest.approx(1.0, abs=RAD)
    assert st.velocity == pytest.approx(-1000 * RAD)
    assert st.current == pytest.approx(-0.2)
    assert st.torque == pytest.approx(-0.2 * KT)
    b.joint.set_velocity(0.5)
    assert b.slave.get("target_speed") == -counts(0.5)
    b.joint.set_torque(2.0)
    assert b.slave.get("target_current") == round(-2.0 / KT * 1000)


def test_offset_shifts_the_zero() -> None:
    b = bench(enabled=True, offset=0.25)
    b.joint.move_to(0.25)
    assert b.slave.get("target_absolute_position") == 0
    b.slave.set("actual_position", 0)
    assert b.joint.state().position == pytest.approx(0.25)


def test_numpy_scalars_are_accepted() -> None:
    b = bench(enabled=True)
    b.joint.move_to(np.float32(0.5))
    assert b.slave.get("target_absolute_position") == counts(float(np.float32(0.5)))
    b.joint.set_velocity(np.float64(0.1))
    assert b.slave.get("target_speed") == counts(0.1)


# --- checks before anything is sent -----------------------------------------------------------

LIMITS = Limits(position=(-1.0, 1.0), velocity=1.0, torque=5.0, acceleration=10.0)


@pytest.mark.parametrize(
    "command",
    [
        lambda j: j.move_to(1.5),
        lambda j: j.move_to(-1.0001),
        lambda j: j.move_to(0.5, velocity=1.5),
        lambda j: j.move_to(0.5, velocity=0.0),
        lambda j: j.move_to(0.5, velocity=-0.5),
        lambda j: j.move_to(0.5, acceleration=20.0),
        lambda j: j.move_to(0.5, deceleration=0.0),
        lambda j: j.move_to(0.5, acceleration=-1.0),
        lambda j: j.set_velocity(1.5),
        lambda j: j.set_velocity(-1.5),
        lambda j: j.set_velocity(0.5, acceleration=11.0),
        lambda j: j.set_torque(5.5),
        lambda j: j.set_torque(-6.0),
        lambda j: j.move_by(2.5),
    ],
    ids=["pos-high", "pos-low", "profile-vel", "zero-vel", "neg-vel", "accel", "zero-decel", "neg-accel",
         "vel", "neg-vel-cmd", "vel-accel", "torque", "neg-torque", "move-by"],
)
def test_out_of_limit_commands_send_nothing(command) -> None:  # type: ignore[no-untyped-def]
    b = bench(limits=LIMITS, enabled=True)
    before = b.sent()
    with pytest.raises(CommandError) as info:
        command(b.joint)
    assert "shoulder" in str(info.value)
    assert b.sent() == before
    assert b.slave.get("status_of_achieving_position") == AchieveStatus.MOTOR_ON  # still standing


def test_limit_message_names_the_value_and_the_limit() -> None:
    b = bench(limits=LIMITS, enabled=True)
    with pytest.raises(CommandError, match=r"position 1\.5000 rad is outside the limits \[-1\.0000, 1\.0000\]"):
        b.joint.move_to(1.5)
    with pytest.raises(CommandError, match="nothing was sent"):
        b.joint.set_torque(6.0)


BAD_NUMBERS = [math.nan, math.inf, -math.inf, "1.0", None, True, 1j]


@pytest.mark.parametrize("value", BAD_NUMBERS, ids=repr)
@pytest.mark.parametrize("call", ["move_to", "set_velocity", "set_torque", "move_by"])
def test_non_finite_commands_send_nothing(call: str, value: object) -> None:
    b = bench(enabled=True)  # no limits: the finiteness check alone must stop it
    before = b.sent()
    with pytest.raises(CommandError, match="finite number"):
        getattr(b.joint, call)(value)
    assert b.sent() == before


@pytest.mark.parametrize("kw", ["velocity", "acceleration", "deceleration"])
@pytest.mark.parametrize("value", [math.nan, math.inf])
def test_non_finite_profile_arguments_send_nothing(kw: str, value: float) -> None:
    b = bench(enabled=True)
    before = b.sent()
    with pytest.raises(CommandError):
        b.joint.move_to(0.1, **{kw: value})
    assert b.sent() == before


@pytest.mark.parametrize(
    "command",
    [lambda j: j.move_to(0.1), lambda j: j.set_velocity(0.1), lambda j: j.set_torque(1.0)],
    ids=["move_to", "set_velocity", "set_torque"],
)
def test_commands_while_disabled_raise_state_error(command) -> None:  # type: ignore[no-untyped-def]
    b = bench()
    with pytest.raises(StateError, match="not enabled"):
        command(b.joint)
    assert b.sent() == []


def test_commands_after_disable_raise_state_error() -> None:
    b = bench(enabled=True)
    b.joint.disable()
    before = b.sent()
    with pytest.raises(StateError):
        b.joint.move_to(0.1)
    assert b.sent() == before


def test_limit_check_comes_before_the_state_check() -> None:
    b = bench(limits=LIMITS)
    with pytest.raises(CommandError):
        b.joint.move_to(3.0)


# --- power ------------------------------------------------------------------------------------


def test_enable_disable_write_the_enable_register() -> None:
    b = bench()
    b.joint.enable()
    assert b.joint.enabled
    assert b.slave.get("status_of_achieving_position") == AchieveStatus.MOTOR_ON
    b.joint.disable()
    assert not b.joint.enabled
    assert b.slave.writes("enable_the_motor") == [1, 0]
    assert b.slave.get("control_source") == 0


def test_stop_and_emergency_stop() -> None:
    b = bench(enabled=True)
    b.joint.move_to(0.5)
    b.joint.stop()
    assert b.slave.write_log[-1] == ("stop_operating", 0)
    b.joint.emergency_stop()
    assert b.slave.write_log[-1] == ("emergency_stop", 1)


# --- registers --------------------------------------------------------------------------------


def test_read_and_write_by_name_and_address() -> None:
    b = bench()
    b.joint.write("profile_speed", 10000)
    assert b.slave.get("profile_speed") == 10000
    assert b.joint.read("profile_speed") == 10000
    assert b.joint.read(0x0047) == 10000
    b.joint.write(0x0047, 20000)
    assert b.slave.get("profile_speed") == 20000
    b.slave.set("actual_position", -123456)  # int32, Hi word first
    assert b.joint.read("actual_position") == -123456
    assert b.joint.read(0x0066) == -123456
    assert b.slave.write_log == [("profile_speed", 10000), ("profile_speed", 20000)]


def test_unknown_register_raises_register_error() -> None:
    b = bench()
    with pytest.raises(RegisterError, match="no register named"):
        b.joint.read("actual_postion")
    with pytest.raises(RegisterError, match="second word"):
        b.joint.write(0x0048, 1)  # low word of profile_speed
    assert b.sent() == []


def test_write_to_read_only_register_sends_nothing() -> None:
    b = bench()
    with pytest.raises(RegisterError, match="read-only"):
        b.joint.write("actual_position", 5)
    assert b.sent() == []


def test_write_out_of_register_range_sends_nothing() -> None:
    b = bench()
    with pytest.raises(CommandError):
        b.joint.write("modbus_communication_timeout_duration", 5000)  # 0..4000 ms
    with pytest.raises(CommandError):
        b.joint.write("profile_speed", 1.5)  # type: ignore[arg-type]
    assert b.sent() == []


@pytest.mark.parametrize("name,value", [("modbus_baud_rate", 4), ("modbus_address", 5), ("save_parameters", 2)])
def test_persistent_write_needs_confirmation(name: str, value: int) -> None:
    b = bench()
    with pytest.raises(ConfirmationRequired, match="confirm=True"):
        b.joint.write(name, value)
    assert b.sent() == []
    b.joint.write(name, value, confirm=True)
    assert b.slave.write_log == [(name, value)]


# --- wait -------------------------------------------------------------------------------------


def test_wait_returns_when_the_motion_ends() -> None:
    b = bench(enabled=True, move_reads=4)
    b.joint.move_to(0.5)
    assert b.joint.state().moving
    t0 = b.clock.now()
    st = b.joint.wait(timeout=5.0, poll=0.01)
    assert not st.moving
    assert st.position == pytest.approx(0.5, abs=RAD)
    assert b.clock.now() > t0  # it polled on the injected clock, no wall-clock sleep
    assert b.clock.now() - t0 < 0.1


def test_wait_returns_at_once_when_standing() -> None:
    b = bench(enabled=True)
    t0 = b.clock.now()
    assert not b.joint.wait().moving
    assert b.clock.now() == t0


def test_wait_until_condition() -> None:
    b = bench(enabled=True)
    b.slave.set("actual_position", 1000)
    st = b.joint.wait(until=lambda s: s.position > 0)
    assert st.position == pytest.approx(1000 * RAD)


def test_wait_raises_device_fault_with_the_manual_text() -> None:
    b = bench(enabled=True, move_reads=1000)
    b.joint.move_to(0.5)
    b.slave.fault(0x0FA2)
    with pytest.raises(DeviceFault) as info:
        b.joint.wait(timeout=1.0)
    err = info.value
    assert err.code == 0x0FA2
    assert "RS485 communication timeout" in str(err)
    assert "0x0FA2" in str(err) and "shoulder" in str(err)


def test_check_raises_on_fault_and_clear_faults() -> None:
    b = bench()
    b.joint.check()
    b.slave.fault(0x0FA2)
    with pytest.raises(DeviceFault, match="RS485 communication timeout"):
        b.joint.check()
    b.joint.clear_faults()
    b.joint.check()


def test_wait_times_out_on_the_injected_clock() -> None:
    b = bench(enabled=True, move_reads=10**6)
    b.joint.move_to(0.5)
    t0 = b.clock.now()
    with pytest.raises(MotionTimeout, match="still moving") as info:
        b.joint.wait(timeout=0.5, poll=0.05)
    assert isinstance(info.value, TimeoutError)
    assert b.clock.now() - t0 == pytest.approx(0.5)


@pytest.mark.parametrize("kw", [{"poll": 0.0}, {"poll": -1.0}, {"timeout": math.nan}, {"poll": math.inf},
                                {"timeout": -1.0}])
def test_wait_rejects_bad_timing(kw: dict[str, float]) -> None:
    b = bench(enabled=True, move_reads=10**6)
    b.joint.move_to(0.5)
    with pytest.raises(CommandError):
        b.joint.wait(**kw)


# --- shutdown (what the rig calls on exit) ----------------------------------------------------


def test_shutdown_stops_and_disables_an_enabled_joint() -> None:
    b = bench(enabled=True)
    b.joint.shutdown()
    assert b.slave.write_log[-2:] == [("stop_operating", 0), ("enable_the_motor", 0)]
    assert not b.joint.enabled


def test_shutdown_leaves_a_never_enabled_joint_alone() -> None:
    b = bench()
    b.joint.shutdown()
    assert b.sent() == []


def test_shutdown_disables_a_joint_enabled_by_a_raw_register_write() -> None:
    b = bench()
    b.joint.write("enable_the_motor", 1)
    b.joint.shutdown()
    assert b.slave.write_log[-1] == ("enable_the_motor", 0)


def test_direction_must_be_plus_or_minus_one() -> None:
    slave = FakeErob(2)
    clock = ManualClock()
    link = ModbusLink(LoopbackTransport(slave.bus()), clock=clock)
    with pytest.raises(CommandError):
        Joint("j", ErobModbusDriver(link, 2, clock=clock), clock=clock, direction=2)


# --- the per-step paths: inlined checks and conversions are the helpers' bits --------------------


@pytest.mark.parametrize(("direction", "offset", "lead"), [(1, 0.0, None), (-1, 0.37, None), (-1, 0.01, 0.005)])
def test_step_commands_and_state_are_the_helpers_bits(direction: int, offset: float, lead: float | None) -> None:
    """position/velocity/torque_command and to_si inline _to_pos, _to_vel, _to_acc, _to_current and _from_pos
    (the per-step path): the same numbers, bit for bit, for any direction, offset and lead."""
    slave = FakeErob(2)
    clock = ManualClock()
    driver = ErobModbusDriver(ModbusLink(LoopbackTransport(slave.bus()), clock=clock), 2, clock=clock)
    j = Joint("j", driver, clock=clock, direction=direction, offset=offset, lead=lead,
              limits=Limits(position=(-3.0, 3.0), velocity=4.0, torque=30.0),
              motion=Motion(velocity=1.3, acceleration=7.7, deceleration=5.1))
    j.enable()
    rng = np.random.default_rng(3)
    for x in rng.uniform(-1.0, 1.0, 200).tolist():
        target, speed, acc, dec = j.position_command(3.0 * x)
        assert (target, speed, acc, dec) == (j._to_pos(3.0 * x), abs(j._to_vel(1.3)), j._to_acc(7.7), j._to_acc(5.1))
        assert j.velocity_command(4.0 * x) == (j._to_vel(4.0 * x), j._to_acc(7.7))
        assert j.torque_command(30.0 * x) == j._to_current(30.0 * x)
    for counts_, speed_, amps in zip(rng.integers(-2**31, 2**31, 50).tolist(), rng.integers(-2**20, 2**20, 50).tolist(),
                                      rng.integers(-30000, 30000, 50).tolist()):
        raw = RawState(counts_, speed_, amps, 40.0, True, False, 0, 1.5)
        s = j.to_si(raw)
        u = j.units
        assert s.position == j._from_pos(counts_)  # exact: the same operations in the same order
        assert s.velocity == speed_ * u.velocity * j.scale * direction
        assert s.current == amps * u.current * direction
        assert s.torque == s.current * u.torque_constant / j.scale
        assert (s.temperature, s.enabled, s.moving, s.fault, s.time, s.raw) == (40.0, True, False, None, 1.5, raw)
        assert j.last_state is s and j.last_contact == 1.5


def test_step_commands_refuse_in_the_same_order() -> None:
    """The inlined checks raise the helpers' errors in the helpers' order: finite, limit, fault, enabled."""
    b = bench(limits=Limits(position=(-1.0, 1.0), velocity=1.0, torque=5.0))
    j = b.joint
    with pytest.raises(CommandError, match="position must be a finite number"):
        j.position_command(math.nan)
    with pytest.raises(LimitError, match="outside the limits"):  # the limit before the (disabled) state
        j.position_command(1.5)
    with pytest.raises(LimitError, match="velocity 2.0000 rad/s exceeds"):
        j.velocity_command(2.0)
    with pytest.raises(LimitError, match="torque 6.000 N\\*m exceeds"):
        j.torque_command(6.0)
    for call in (lambda: j.position_command(0.5), lambda: j.position_command(0.25),  # profile new, then known
                 lambda: j.velocity_command(0.5), lambda: j.torque_command(1.0)):
        with pytest.raises(StateError, match="not enabled"):
            call()
    j.enable()
    b.slave.fault(0x0FA2)
    j.state()
    for call in (lambda: j.position_command(0.5), lambda: j.velocity_command(0.5), lambda: j.torque_command(1.0)):
        with pytest.raises(DeviceFault):
            call()
    with pytest.raises(CommandError, match="acceleration must be > 0"):
        j.velocity_command(0.5, -1.0)


def test_slots_maker_makes_the_dataclass_object() -> None:
    """The per-read state objects are made by slots_maker: equal to the dataclass's own, every field set."""
    values = (0.5, -1.25, 3.0, 0.2, 41.0, True, False, None, 2.5, RawState(1, 2, 3.0, 4.0, True, False, 0, 2.5))
    made = slots_maker(JointState)(*values)
    ref = JointState(*values)
    assert type(made) is JointState and made == ref and repr(made) == repr(ref) and hash(made) == hash(ref)
    assert [getattr(made, f.name) for f in dataclasses.fields(JointState)] == list(values)
    raw = raw_state(1, 2, 3.0, 4.0, True, False, 7, 0.5, {"a": 1})
    assert raw == RawState(1, 2, 3.0, 4.0, True, False, 7, 0.5, {"a": 1}) and raw.extra == {"a": 1}
    with pytest.raises(dataclasses.FrozenInstanceError):
        made.position = 1.0  # type: ignore[misc]

    @dataclass(frozen=True)
    class NoSlots:
        x: int

    with pytest.raises(TypeError):
        slots_maker(NoSlots)
