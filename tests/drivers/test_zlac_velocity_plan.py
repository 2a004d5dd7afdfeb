"""ZlacDrive.velocity_plan (what Rig.set_velocities and the compiled path send): the same plans, frames and
mode bookkeeping as the rule it implements, which this test writes out; its steady case (the drive already in
velocity mode) skips require_mode and is taken."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import pytest

from joints.clock import ManualClock
from joints.devices.zlac.profile import HubMotorProfile
from joints.devices.zlac.registers import ZLAC8015D, ControlMode
from joints.drivers.zlac_modbus import SIDES, ZlacChannelDriver, ZlacDrive, ramp_time_ms
from joints.errors import CommandError, StateError
from joints.link.modbus import ModbusLink
from joints.link.trace import Trace
from joints.sim.modbus_front import ModbusDeviceBus, ModbusFront
from joints.sim.zlac import ZlacFirmware
from joints.transports.loopback import LoopbackTransport


class _Profile:
    torque_constant = 0.8


def rule(drive: ZlacDrive, commands: Mapping[str, tuple[int, int]]) -> tuple[dict[str, int] | None, dict[str, int]]:
    """The plan as the driver's docstring states it, name by name (require_mode for each wheel)."""
    rpm = {side: round(commands[side][0] / 10.0) for side in SIDES}
    for side in SIDES:
        ZLAC8015D[f"target_velocity_{side}"].check(rpm[side])
    drive._need_both("set_velocities")
    ramps: dict[str, int] = {}
    for side in SIDES:
        drive.require_mode(side, ControlMode.VELOCITY)
        last = drive.written(f"target_velocity_{side}", 0)
        ms = ramp_time_ms(rpm[side] - last, commands[side][1] / 10.0) if rpm[side] != last else None
        for stem in ("acceleration_time", "deceleration_time"):
            name = f"{stem}_{side}"
            ramps[name] = drive.written(name, 500) if ms is None else ms
    changed = any(drive.written(k, -1) != v for k, v in ramps.items())
    return (ramps if changed else None), {f"target_velocity_{side}": rpm[side] for side in SIDES}


def _drive() -> tuple[ZlacDrive, Trace]:
    trace = Trace()
    fw = ZlacFirmware(HubMotorProfile(), 1)
    link = ModbusLink(LoopbackTransport(ModbusDeviceBus([ModbusFront(fw, ZLAC8015D, 1)])), clock=ManualClock(),
                      trace=trace)
    drive = ZlacDrive(link, 1)
    for side in SIDES:
        ZlacChannelDriver(drive, side, profile=_Profile())
    for side in SIDES:  # enabled in no mode yet: the first plan sets velocity mode
        drive.enable(side)
    return drive, trace


COMMANDS: list[dict[str, tuple[int, int]]] = [
    {"left": (1000, 5000), "right": (-1000, 5000)},  # no mode yet: the left wheel's require_mode writes it
    {"left": (1000, 5000), "right": (-1000, 5000)},  # the same: no ramps
    {"left": (1204, 2500), "right": (-796, 900)},
    {"left": (1204, 2500), "right": (300, 900)},  # one wheel changes
    {"left": (-2999, 100), "right": (0, 100000)},
]


def _run(plan: Any) -> tuple[list[Any], list[str], Any, Trace]:
    drive, trace = _drive()
    out = []
    for cmd in COMMANDS:
        ramps, targets = plan(drive, cmd)
        out.append((ramps, targets, dict(drive.state.channel_mode), drive.state.mode))
        if ramps is not None:
            drive.set_block(ramps)
        drive.set_block(targets)
    frames = [r.data.hex() for r in trace if r.direction == "tx"]
    return out, frames, drive, trace


def test_the_plan_is_the_rule_and_the_steady_case_skips_require_mode(monkeypatch: pytest.MonkeyPatch) -> None:
    want, want_frames, _, _ = _run(rule)
    calls: list[str] = []
    original = ZlacDrive.require_mode

    def counted(self: ZlacDrive, side: str, mode: ControlMode) -> None:
        calls.append(side)
        original(self, side, mode)

    monkeypatch.setattr(ZlacDrive, "require_mode", counted)
    got, got_frames, _, _ = _run(ZlacDrive.velocity_plan)
    assert got == want
    assert got_frames == want_frames
    assert got[0][3] == ControlMode.VELOCITY and "0106200d0003" in "".join(got_frames)  # the mode was written
    assert calls == ["left"]  # only before the mode was the drive's; then the steady case


def test_refusals_come_in_the_rule_s_order() -> None:
    drive, _ = _drive()
    with pytest.raises(CommandError):
        drive.velocity_plan({"left": (40000, 100), "right": (0, 100)})
    drive.disable("right")
    with pytest.raises(CommandError):  # the range check before the enable check
        drive.velocity_plan({"left": (0, 100), "right": (40000, 100)})
    with pytest.raises(StateError, match="right"):
        drive.velocity_plan({"left": (0, 100), "right": (0, 100)})
