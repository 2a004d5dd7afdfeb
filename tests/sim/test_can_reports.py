"""The eRob CAN one-call exchange's steady proofs and its reads' sensor reports (joints.sim.can_exchange).

- The stock-method check: a method replaced on a base of the host link's class is seen at the next step, and
  once put back the steps take the call again.
- The reads' sensor reports made inside the compiled call (``report``): with noisy sensors (every draw of the
  model: sample age, position, velocity and current noise) and several seeds, the compiled path gives the frame by
  frame path's bits (the sensors' streams and sample ages among them) and made the reports in its calls; a sensor
  drawing from a generator set as its ``rng``, or with a replaced read, falls back to the firmware's reports in
  Python, with the same bits; a value that is not finite raises at the host as the firmware's ``round`` raises.
"""

from __future__ import annotations

import functools
import math
import random
from typing import Any

import numpy as np
import pytest
from test_can_exchange import _run, _same

from joints.drivers.erob_can_steady import ErobCanStep
from joints.link.base import Link
from joints.sim import can_exchange as CE
from joints.sim import erob_kernel as K
from joints.sim import kernel, sensors
from joints.sim.sensors import Sensor, SensorModel

#: every draw of a sensor read: the sample age, position, velocity and current noise (and the estimate's window)
NOISY = SensorModel(velocity_window=0.001, velocity_noise=0.02, position_noise=2e-4, current_noise=0.05,
                    current_resolution=0.002, sample_jitter=2e-4)


def _steps(u: Any) -> list[ErobCanStep]:
    return [s for s in (u.compiled_path._steppers if u.compiled_path else []) if isinstance(s, ErobCanStep)]


# -- the stock-method check --------------------------------------------------------------------------------
def test_a_method_replaced_on_a_base_of_the_host_s_link_leaves_the_steps_to_the_frame_by_frame_path(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """From step 10 ``Link._drain`` (on the base of the link's class) is wrapped, from step 20 put back: the call
    carries none of steps 10-19 and carries the others, with the same bits."""
    original = Link._drain
    calls: list[int] = []

    def plant(k: int, u: Any) -> None:
        if k == 10:
            monkeypatch.setattr(Link, "_drain", lambda self, *a, **kw: original(self, *a, **kw))
        elif k == 20:
            monkeypatch.setattr(Link, "_drain", original)
        steps = _steps(u)
        if steps:
            (step,) = steps
            calls.append(step.values_taken)

    out = {}
    for compiled in (False, True):
        monkeypatch.setattr(Link, "_drain", original)
        calls.clear()
        out[compiled] = _run(compiled, "position", 30, plant=plant)
    _same(out[False], out[True])
    if kernel.default_mode():
        assert calls[10] > calls[1] > 0 and calls[10] == calls[20] and calls[-1] >= calls[20] + 9


# -- the sensor reports in the call -------------------------------------------------------------------------
def _noisy(seed: int) -> Any:
    def plant(k: int, u: Any) -> None:
        if k == 0:
            world = u.rig.sim
            sensors.scale(world, 1.0, model=NOISY)
            sensors.seed(world, seed)
    return plant


def _reported(u: Any) -> int:
    return sum(s.exchange.reported for s in _steps(u))


@pytest.mark.parametrize(("mode", "seed"), [("position", 1), ("position", 77), ("velocity", 5), ("torque", 123456)])
def test_the_reads_sensor_reports_made_in_the_call_give_the_frame_by_frame_bits(mode: str, seed: int) -> None:
    steps = 60
    reported: list[int] = []
    plant = _noisy(seed)

    def counting(k: int, u: Any) -> None:
        plant(k, u)
        reported.append(_reported(u))

    driver = _run(False, mode, steps, plant=plant)
    compiled = _run(True, mode, steps, plant=counting)
    _same(driver, compiled)
    if kernel.default_mode():
        assert compiled["values"] >= steps - 1
        assert reported[-1] >= steps - 2  # every state read's reports made in its call


def test_a_sensor_drawing_from_a_generator_of_its_own_reports_in_python(monkeypatch: pytest.MonkeyPatch) -> None:
    """From step 10 the sensor draws from a ``random.Random`` set as its ``rng``; from step 20 a read of
    :class:`Sensor` is replaced: the call makes no report from step 10 (then is not taken at all), the same bits."""
    original = Sensor.velocity
    seen: list[tuple[int, int]] = []
    plant = _noisy(9)

    def planting(k: int, u: Any) -> None:
        plant(k, u)
        if k == 10:
            for s in sensors.sensors_of(u.rig.sim):
                s.rng = random.Random(31)
        elif k == 20:
            monkeypatch.setattr(Sensor, "velocity", lambda self, q, v: original(self, q, v))
        steps = _steps(u)
        if steps:
            seen.append((_reported(u), steps[0].values_taken))

    out = {}
    for compiled in (False, True):
        monkeypatch.setattr(Sensor, "velocity", original)
        seen.clear()
        out[compiled] = _run(compiled, "position", 30, plant=planting)
    _same(out[False], out[True])
    if kernel.default_mode():
        assert seen[10][0] > seen[1][0] > 0 and seen[10][0] == seen[-1][0]  # no report in a call from step 10
        assert seen[20][1] > seen[10][1] and seen[20][1] == seen[-1][1]  # the calls went on to step 20, then none


@functools.cache
def _compiled_report() -> Any:
    """:func:`joints.sim.can_exchange.report` compiled, once per test session."""
    return kernel.compiled(CE.report)


@pytest.mark.skipif(not kernel.default_mode(), reason="the reports are made in the compiled call")
@pytest.mark.parametrize("kind", [CE.REPORT_POSITION, CE.REPORT_SPEED, CE.REPORT_CURRENT, CE.REPORT_ALL])
@pytest.mark.parametrize("bad", [None, math.nan, math.inf, -math.inf, 1e300])
def test_a_report_gives_the_firmware_s_value_or_raises_at_the_host_as_its_round_raises(kind: int,
                                                                                      bad: float | None) -> None:
    """``report`` (compiled, on a sensor's rows) gives the value the firmware's method gives, after the same draws;
    where that method's ``round`` raises (a value that is not finite), the value is left in the read's status value
    as it is, the host's ``int`` of it raises the same, and the call's later reads make no report."""
    ours, theirs = Sensor(NOISY, "erob:1", K.COUNTS_PER_RAD), Sensor(NOISY, "erob:1", K.COUNTS_PER_RAD)
    row = np.zeros(K.WIDTH)
    row[K.OFFSET] = 1234.0
    o = np.zeros(CE.OUT_WIDTH)
    cols = [0.25, 4000.0, -900.0, 1500.0]  # time, position and velocity [count], current [mA]
    if bad is not None:  # (the position, the velocity, the current; the status read's velocity)
        cols[{CE.REPORT_POSITION: 1, CE.REPORT_SPEED: 2, CE.REPORT_CURRENT: 3, CE.REPORT_ALL: 2}[kind]] = bad
    o[CE.SENSED_AT:] = cols
    t = np.zeros(CE.TX_WIDTH)
    t[CE.SENSE] = kind
    st = np.zeros(CE.STATE_WIDTH)
    st[CE.REPORTS] = 1.0
    _compiled_report()(row, t, o, st, ours.state, ours._m)
    at = {CE.REPORT_POSITION: CE._AT_POSITION, CE.REPORT_SPEED: CE._AT_SPEED, CE.REPORT_CURRENT: CE._AT_CURRENT,
          CE.REPORT_ALL: CE._AT_ACHIEVE}[kind]
    time, pos, vel, i = cols
    c = K.COUNTS_PER_RAD
    try:
        if kind == CE.REPORT_POSITION:
            want: Any = round(theirs.position(time, pos / c, vel / c) * c) + 1234
        elif kind == CE.REPORT_SPEED:
            want = round(theirs.velocity(pos / c, vel / c) * c)
        elif kind == CE.REPORT_CURRENT:
            want = round(theirs.current(i * 1e-3) * 1e3)
        else:
            p, v, cur = theirs.sense(time, pos / c, vel / c, i * 1e-3)
            want = (round(p * c) + 1234, round(v * c), round(cur * 1e3))
    except (ValueError, OverflowError) as exc:
        with pytest.raises(type(exc), match=str(exc)):
            int(o[at])
        assert st[CE.REPORTS] == 0.0
    else:
        assert st[CE.REPORTS] == 1.0
        if kind == CE.REPORT_ALL:
            assert o[at] == 0.0  # (the status read's own value left as it was: its three values unused)
        else:  # (past int32 the host saturates: the same bound)
            lo, hi = -(1 << 31), (1 << 31) - 1
            assert max(lo, min(hi, int(o[at]))) == max(lo, min(hi, want))
    assert ours.stream.getstate() == theirs.stream.getstate() and repr(ours._age) == repr(theirs._age)
    if bad is None:
        assert ours.stream.getstate() != Sensor(NOISY, "erob:1", K.COUNTS_PER_RAD).stream.getstate()  # (drew)
