"""The twins' kernels give the same bits compiled (numba) and as plain Python, from any state.

Random drive states and commands (hypothesis) are stepped through both versions of the same
functions; every column of the rows and every torque must be equal. Scenario-level identity
(whole worlds, drivers and envs) is tests/sim/test_twin_golden.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from joints.devices.erob.profiles import profile as erob_profile
from joints.devices.zlac.profile import DEFAULT_MODEL
from joints.devices.zlac.profile import profile as zlac_profile
from joints.errors import ParameterRefused
from joints.sim import erob_kernel as K
from joints.sim import kernel
from joints.sim import zlac_kernel as Z
from joints.sim.erob import ErobFirmware
from joints.sim.zlac import ZlacFirmware

pytestmark = pytest.mark.skipif(not kernel.AVAILABLE, reason="numba not installed (the `fast` extra)")

EROB_COMMANDS = [
    [("enable_the_motor", 1)],
    [("operation_mode", 3), ("motion_mode", 1), ("target_absolute_position", 40_000), ("start_operating", 1)],
    [("operation_mode", 3), ("motion_mode", 0), ("profile_speed", -30_000), ("start_operating", 1)],
    [("operation_mode", 3), ("motion_mode", 2), ("target_absolute_position", -20_000), ("dwell_time", 100),
     ("start_operating", 1)],
    [("operation_mode", 2), ("target_speed", 60_000)],
    [("operation_mode", 1), ("target_current", 2500)],
    [("stop_operating", 1)],
    [("emergency_stop", 1)],
    [("clear_errors", 1)],
    [("modbus_communication_timeout_duration", 5)],
    [("max_position_error", 300)],
]
finite = st.floats(-5.0, 5.0, allow_nan=False)


def _twins() -> tuple[ErobFirmware, ErobFirmware]:
    a, b = ErobFirmware(erob_profile("eRob80H100"), 1), ErobFirmware(erob_profile("eRob80H100"), 1)
    b.adopt(np.zeros((1, K.WIDTH)), 0)  # b runs on a numpy row: compiled helpers
    return a, b


def _write(fw: ErobFirmware | ZlacFirmware, items: list[tuple[str, int]]) -> str:
    """Write ``items`` (a refused write is refused by both versions alike)."""
    try:
        fw.write_many(items)
    except ParameterRefused as exc:
        return str(exc)
    return "ok"


def _equal(x: list[float], y: list[float]) -> bool:
    return all(p == q or (math.isnan(p) and math.isnan(q)) for p, q in zip(x, y))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, len(EROB_COMMANDS) - 1), st.integers(1, 400), finite, finite),
                min_size=1, max_size=8))
def test_erob_kernel_compiled_is_python(script: list[tuple[int, int, float, float]]) -> None:
    py, nb = _twins()
    step_c = K.compiled_ops().step
    t = 0.0
    for cmd, substeps, q0, qd in script:
        assert _write(py, EROB_COMMANDS[cmd]) == _write(nb, EROB_COMMANDS[cmd])
        for k in range(substeps):
            t += 0.001
            q = q0 + 0.01 * math.sin(k * 0.01)
            tau_p = K.step(py._row, t, 0.001, q, qd)
            tau_c = step_c(nb._row, t, 0.001, q, qd)
            assert tau_p == tau_c
        assert _equal(py._row, nb._row.tolist())
        assert py.read_many(("status_of_achieving_position", "motion_status")) == \
            nb.read_many(("status_of_achieving_position", "motion_status"))


ZLAC_COMMANDS = [
    [("control_mode", 3), ("control_word", 0x08), ("target_velocity_left", 120), ("target_velocity_right", -80)],
    [("control_mode", 1), ("control_word", 0x08), ("target_position_left", 5000), ("target_position_right", -3000),
     ("control_word", 0x11)],
    [("control_mode", 4), ("control_word", 0x08), ("target_torque_left", 3000), ("target_torque_right", -2000)],
    [("control_word", 0x05)],
    [("control_word", 0x07)],
    [("control_word", 0x06)],
    [("communication_offline_time", 5)],
]


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(0, len(ZLAC_COMMANDS) - 1), st.integers(1, 300), finite, finite, finite),
                min_size=1, max_size=6))
def test_zlac_kernel_compiled_is_python(script: list[tuple[int, int, float, float, float]]) -> None:
    py, nb = ZlacFirmware(zlac_profile(DEFAULT_MODEL), 1), ZlacFirmware(zlac_profile(DEFAULT_MODEL), 1)
    nb.adopt(np.zeros((3, Z.WIDTH)), 0)
    step_c = Z.compiled_ops().step
    t = 0.0
    for cmd, substeps, ql, qr, qd in script:
        assert _write(py, ZLAC_COMMANDS[cmd]) == _write(nb, ZLAC_COMMANDS[cmd])
        for k in range(substeps):
            t += 0.001
            for side, q in ((0, ql + k * 1e-3), (1, qr - k * 1e-3)):
                tau_p = Z.step(py._table, 0, side, t, 0.001, q, qd)
                tau_c = step_c(nb._table, 0, side, t, 0.001, q, qd)
                assert tau_p == tau_c
        for r in range(3):
            assert _equal(py._table[r], nb._table[r].tolist())


@pytest.mark.parametrize(("compiled", "jit", "expected"), [
    (None, None, True), ("0", None, False), (None, "0", False), ("1", "0", True), ("0", "1", False)])
def test_one_switch_for_the_compiled_path_and_its_old_name(monkeypatch: pytest.MonkeyPatch, compiled: str | None,
                                                           jit: str | None, expected: bool) -> None:
    """``JOINTS_COMPILED=0`` turns the compiled kernels off; the old ``JOINTS_JIT`` still does where it is unset."""
    for name, value in ((kernel.SWITCH, compiled), (kernel.OLD_SWITCH, jit)):
        if value is None:
            monkeypatch.delenv(name, raising=False)
        else:
            monkeypatch.setenv(name, value)
    assert kernel.default_mode() is (expected and kernel.AVAILABLE)


def test_a_world_is_compiled_by_its_own_argument_and_its_old_name(monkeypatch: pytest.MonkeyPatch) -> None:
    """``World(compiled=...)`` overrides the switch; ``World(jit=...)``, its older name, still does (deprecated)."""
    from joints.sim.world import World

    monkeypatch.delenv(kernel.SWITCH, raising=False)
    monkeypatch.delenv(kernel.OLD_SWITCH, raising=False)
    assert World("erob_stand.xml", [], buses={}).compiled is kernel.AVAILABLE
    assert World("erob_stand.xml", [], buses={}, compiled=False).compiled is False
    assert World("erob_stand.xml", [], buses={}, compiled=True).compiled is kernel.AVAILABLE
    with pytest.warns(DeprecationWarning, match="compiled="):
        assert World("erob_stand.xml", [], buses={}, jit=False).compiled is False
    monkeypatch.setenv(kernel.SWITCH, "0")
    assert World("erob_stand.xml", [], buses={}).compiled is False
    assert World("erob_stand.xml", [], buses={}, compiled=True).compiled is kernel.AVAILABLE
