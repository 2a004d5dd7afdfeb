"""MKS drive semantics: work modes, codes (kept equal to the codec's), run state machine, speed laws."""

from __future__ import annotations

import enum

import pytest

from joints.codecs import mks as codec
from joints.devices.mks import state
from joints.devices.mks.state import RunEvent, RunState, RunStatus, WorkMode, step
from testdata import by_id


def test_work_modes_and_their_maximum_speeds() -> None:
    assert [m.value for m in WorkMode] == list(range(6))
    assert {m.name: m.max_speed for m in WorkMode} == {
        "CR_OPEN": 400, "CR_CLOSE": 1500, "CR_vFOC": 3000, "SR_OPEN": 400, "SR_CLOSE": 1500, "SR_vFOC": 3000}
    assert [m.serial for m in WorkMode] == [False] * 3 + [True] * 3
    assert not WorkMode.SR_OPEN.closed_loop and WorkMode.SR_CLOSE.closed_loop and WorkMode.SR_vFOC.foc


@pytest.mark.parametrize("name", ["SetStatus", "RunStatus", "CalibrationStatus", "GoBackToZeroStatus",
                                  "MotorStatus", "RunDirection"])
def test_codes_equal_the_codecs(name: str) -> None:
    mine: type[enum.IntEnum] = getattr(state, name)
    theirs: type[enum.IntEnum] = getattr(codec, name)
    assert [(m.name, m.value) for m in mine] == [(m.name, m.value) for m in theirs]
    for m in mine:
        assert m == theirs[m.name]


def test_other_value_lists() -> None:
    assert [b.bps for b in state.BaudRate] == [9600, 19200, 25000, 38400, 57600, 115200, 256000]
    assert state.BaudRate.from_bps(115200) is state.BaudRate.B115200
    with pytest.raises(ValueError):
        state.BaudRate.from_bps(12345)
    assert [state.holding_current_percent(h) for h in range(9)] == list(range(10, 100, 10))
    with pytest.raises(ValueError):
        state.holding_current_percent(9)
    assert (state.SpeedModeParameter.SAVE, state.SpeedModeParameter.CLEAN) == (0xC8, 0xCA)
    assert state.IoBit.IN_1 | state.IoBit.OUT_1 == 0b0101


# ------------------------------------------------------------------------------ state machine


def test_the_table_is_complete() -> None:
    assert set(state.TRANSITIONS) == {(s, e) for s in RunState for e in RunEvent}


def test_position_move_with_completion() -> None:
    t = step(RunState.IDLE, RunEvent.START)
    assert t == state.Transition(RunState.RUNNING, RunStatus.STARTED, None)
    t = step(t.state, RunEvent.ARRIVED)
    assert t == state.Transition(RunState.COMPLETE, None, RunStatus.COMPLETE)
    assert not t.state.moving


def test_decelerated_stop_then_stopped() -> None:
    t = step(RunState.RUNNING, RunEvent.STOP)
    assert (t.state, t.reply, t.completion) == (RunState.STOPPING, RunStatus.STARTED, None)
    assert t.state.moving
    t = step(t.state, RunEvent.ARRIVED)
    assert (t.state, t.completion) == (RunState.STOPPED, RunStatus.COMPLETE)


def test_end_limit_and_immediate_and_emergency_stops() -> None:
    assert step(RunState.RUNNING, RunEvent.END_LIMIT) == state.Transition(RunState.END_LIMIT_STOPPED, None,
                                                                          RunStatus.END_LIMIT_STOP)
    assert step(RunState.STOPPING, RunEvent.END_LIMIT).completion is RunStatus.END_LIMIT_STOP
    assert step(RunState.RUNNING, RunEvent.STOP_NOW) == state.Transition(RunState.STOPPED, RunStatus.STARTED,
                                                                         RunStatus.COMPLETE)
    assert step(RunState.RUNNING, RunEvent.EMERGENCY_STOP) == state.Transition(RunState.STOPPED)
    assert step(RunState.RUNNING, RunEvent.PROTECTION) == state.Transition(RunState.STOPPED)


def test_rejects_keep_the_state_and_rest_ignores_motion_events() -> None:
    for s in RunState:
        assert step(s, RunEvent.REJECT) == state.Transition(s, RunStatus.FAIL)
    for s in (RunState.IDLE, RunState.COMPLETE, RunState.STOPPED, RunState.END_LIMIT_STOPPED):
        assert step(s, RunEvent.ARRIVED) == state.Transition(s)
        assert step(s, RunEvent.END_LIMIT) == state.Transition(s)
        assert step(s, RunEvent.STOP).completion is RunStatus.COMPLETE  # stopping a motor at rest completes
    assert step(RunState.RUNNING, RunEvent.START) == state.Transition(RunState.RUNNING, RunStatus.STARTED)


def test_driver_replays_the_manual_position_example() -> None:
    """7.5: FD run -> 01, later 02; a second run -> 01; stop -> 01, later 02 (statuses from the vectors)."""
    ids = by_id()

    def status(vid: str) -> RunStatus:  # the uplink frame's status byte
        frame = bytes.fromhex(ids[vid]["hex"])
        assert frame[:3] == bytes.fromhex("FB 01 FD")
        return RunStatus(frame[3])

    s = RunState.IDLE
    trail = []
    for vid, stop in [("mks-native-7.5-step1-recv1", False), ("mks-native-7.5-step1-recv2", False),
                      ("mks-native-7.5-step2-recv1", False), ("mks-native-7.5-step3-recv1", True),
                      ("mks-native-7.5-step3-recv2", True)]:
        s = step(s, state.event_from_status(status(vid), stop=stop)).state
        trail.append(s)
    assert trail == [RunState.RUNNING, RunState.COMPLETE, RunState.RUNNING, RunState.STOPPING, RunState.STOPPED]
    assert state.event_from_status(0) is RunEvent.REJECT
    assert state.event_from_status(3) is RunEvent.END_LIMIT


def test_motor_status_of_a_ramp() -> None:
    ms = state.motor_status
    assert ms(0, 0) is state.MotorStatus.STOP
    assert ms(100, 600) is state.MotorStatus.SPEED_UP
    assert ms(-700, -600) is state.MotorStatus.SPEED_DOWN
    assert ms(600, -600) is state.MotorStatus.FULL_SPEED
    assert ms(0, 0, homing=True) is state.MotorStatus.HOMING
    assert ms(0, 0, calibrating=True) is state.MotorStatus.CALIBRATING


# ------------------------------------------------------------------------------ laws


def test_acceleration_law() -> None:
    assert state.ramp_interval(236) == pytest.approx(1e-3)  # (256-236) x 50 us
    assert state.acceleration(236) == pytest.approx(1000.0)  # facts: 1000 rpm/s
    assert state.ramp_interval(0) == 0.0 and state.acceleration(0) == float("inf")
    assert state.ramp_time(0, 600, 236) == pytest.approx(0.6)  # the test case
    assert state.ramp_time(0, 3000, 236) == pytest.approx(3.0)  # 6.1 table: 3000 rpm at 3000 ms
    with pytest.raises(ValueError):
        state.ramp_interval(256)


def test_ramp_speed_is_discrete_and_symmetric() -> None:
    assert state.ramp_speed(0, 600, 236, 0.6) == 600
    assert state.ramp_speed(0, 600, 236, 0.3) == 300
    assert state.ramp_speed(0, 600, 236, 0.0005) == 0  # less than one step
    assert state.ramp_speed(0, 3000, 236, 0.002) == 2  # 6.1 table: 2 rpm at 2 ms
    assert state.ramp_speed(600, 0, 236, 0.1) == 500
    assert state.ramp_speed(600, 0, 236, 10.0) == 0
    assert state.ramp_speed(100, -100, 0, 0.0) == -100  # acc 0: at once
    assert state.ramp_speed(-100, 100, 255, 0.001) == -80  # 50 us per step


def test_stopping_distance() -> None:
    # 600 rpm at 1000 rpm/s: 0.6 s at 5 rev/s average -> 3 turns
    assert state.stopping_distance(600, 236) == pytest.approx(3.0)
    assert state.stopping_distance(600, 0) == 0.0


def test_microstep_speed_scaling_as_printed() -> None:
    # 6.1: speed = 1200 -> 8 microsteps 2400 rpm, 16/32/64 1200 rpm, 128 150 rpm
    assert state.effective_rpm(1200, 8) == 2400
    assert [state.effective_rpm(1200, m) for m in (16, 32, 64)] == [1200] * 3
    assert state.effective_rpm(1200, 128) == 150
    assert state.speed_value(150, 128) == 1200 and state.speed_value(2400, 8) == 1200
    assert state.motor_rpm(1200, 8, WorkMode.SR_CLOSE) == 1500  # clamped to the mode
    assert state.motor_rpm(1000, 16, WorkMode.SR_OPEN) == 400
    assert state.motor_rpm(3500, 16, WorkMode.SR_vFOC) == 3000
    with pytest.raises(ValueError):
        state.effective_rpm(100, 0)


def test_resolutions() -> None:
    assert state.pulses_per_turn(16) == 3200
    # 7.5: 0x09C400 pulses at 16 microsteps = 200 turns; 5.2.16: 0x0C80 = 1 turn
    assert 0x09C400 / state.pulses_per_turn(16) == 200 and 0x0C80 == state.pulses_per_turn(16)
    assert state.angle_error_degrees(51200) == 360.0
    assert state.ENCODER_COUNTS_PER_TURN == 0x4000
