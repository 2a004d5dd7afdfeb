"""An eRob status read's values reach the host's state without packing and decoding its words, where that is proven
to give the same values (joints.sim.erob_exchange.StatusReply, joints.compiled_path._ErobModbus._values).

The proof: the twin's read packs its registers' values by type, high word first (``ModbusFront.pack``); the host
decodes the block's registers by type (``RegisterTable.decode_block``). Where both name the same registers (the
same address, type and word order, each wholly in the block) and every value is an int within its register's
type, the decode of the packed words is the values themselves. The twin checks its side once per request shape
(and the values its read does not saturate, per read), the host its side once per reply shape; otherwise the words
are made and decoded as before. The reply message, where the line's log or a host that decodes words asks for
it, is the one the front makes.
"""

from __future__ import annotations

import random
from types import SimpleNamespace
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401 - registers the joints/ envs
from joints.codecs import modbus as mb
from joints.devices.registers import Register
from joints.sim import kernel
from joints.sim.erob_exchange import StatusReply
from joints.sim.modbus_front import ModbusFront

pytestmark = pytest.mark.skipif(not kernel.default_mode(), reason="the one-call exchange needs the compiled world")


def _env(**kwargs: Any) -> Any:
    env = gym.make("joints/ErobReach-v0", **kwargs)
    env.reset(seed=3)
    return env


def _stepper(env: Any) -> Any:
    (stepper,) = env.unwrapped.compiled_path._steppers
    return stepper


def _shape(stepper: Any) -> Any:
    ex = stepper.exchange
    return ex._shape(stepper.status, stepper.lane.framing.size)


def test_the_status_words_decode_to_the_values_for_every_status_register() -> None:
    """Name by name, register by register: the twin's read and the host's decode cover the same registers, and
    the host's decode of the packed words of in-range values gives those values, at each register's type bounds,
    around 0 and at random (the identity the values path rests on)."""
    env = _env()
    try:
        s = _stepper(env)
        shape = _shape(s)
        plan = shape.extra
        assert shape.registers == s._registers  # the twin's registers are the ones the host decodes, in order
        assert [r.name for r in shape.registers] == list(s._names) == list(plan[0].names)
        start, count = s.status.address, s.status.count
        assert all(start <= r.address and r.address + r.words <= start + count for r in shape.registers)
        regs: tuple[Register, ...] = shape.registers
        rng = random.Random(5)
        for k, reg in enumerate(regs):
            lo, hi = reg.type_range
            for v in {lo, lo + 1, hi - 1, hi, 0, 1, max(lo, -1), rng.randint(lo, hi)}:
                values = [0] * len(regs)
                values[k] = v
                words = ModbusFront.pack(plan, values, count)
                assert s.decode(start, words) == dict(zip(s._names, values)), (reg.name, v)
        for _ in range(300):
            values = [rng.randint(*r.type_range) for r in regs]
            assert s.decode(start, ModbusFront.pack(plan, values, count)) == dict(zip(s._names, values))
        # what the read saturates to its register's type needs no check per read; the rest is checked per read
        entries = plan[0].entries
        loose = {k for k, _, _ in shape.loose}
        for k, ((i, name, lo, hi), reg) in enumerate(zip(entries, regs)):
            assert name == reg.name
            if k not in loose:
                assert i >= 0 and reg.type_range[0] <= lo and hi <= reg.type_range[1]
        assert "bus_voltage" in {regs[k].name for k in loose}  # a stored value: the read does not saturate it
        # a read that saturates a value to a range wider than its register's type leaves it to the check per read
        k = s._names.index("actual_position")
        wide = list(entries)
        i, name, lo, hi = wide[k]
        wide[k] = (i, name, lo, hi + 1)
        reader = SimpleNamespace(names=plan[0].names, entries=tuple(wide))
        registers, loose_wide = s.exchange._packed(start, count, (reader, *plan[1:]))
        assert registers == regs
        assert (k, *regs[k].type_range) in loose_wide and len(loose_wide) == len(shape.loose) + 1
        # registers other than the reader's (a shorter block, another order): not packed by values
        assert s.exchange._packed(start, count - 1, plan)[0] is None
        other = SimpleNamespace(names=plan[0].names[::-1], entries=entries)
        assert s.exchange._packed(start, count, (other, *plan[1:]))[0] is None
    finally:
        env.close()


def _joint(env: Any) -> Any:
    (joint,) = env.unwrapped.rig.joints.values()
    return joint


def _device_payloads(env: Any) -> list[Any]:
    return [tx.payload for tx in _joint(env).driver.access.link.transport.log
            if tx.side == "device"]


def _steps(env: Any, n: int) -> list[Any]:
    rng = np.random.default_rng(2)
    out = []
    for _ in range(n):
        obs, reward, terminated, truncated, _info = env.step(rng.uniform(-1, 1, env.action_space.shape))
        out.append((obs.tobytes(), reward, repr(_joint(env).last_state)))
        if terminated or truncated:
            env.reset()
    return out


def test_status_reads_take_the_values_path_with_the_driver_paths_bits_and_replies() -> None:
    compiled, driver = _env(), _env(compiled_path=False)
    try:
        got, want = _steps(compiled, 30), _steps(driver, 30)
        assert got == want
        s = _stepper(compiled)
        assert s.taken_values >= 30  # every step's read took the values path
        assert s.lane.fused >= 3 * 30
        # the line's log holds the replies the front makes (made when read), equal to the driver path's
        mine, theirs = _device_payloads(compiled), _device_payloads(driver)
        assert [type(p) for p in mine] == [type(p) for p in theirs]
        assert mine == theirs
        assert sum(type(p) is mb.ReadRegistersReply for p in mine) >= 30
    finally:
        compiled.close()
        driver.close()


def test_a_stored_value_outside_its_register_goes_by_the_words() -> None:
    """bus_voltage is served from the store without saturation: outside int32 it wraps in the words, and the state
    is the decode of the words (as the driver path's), not the value."""
    env = _env()
    try:
        _steps(env, 2)
        s = _stepper(env)
        fw = s.exchange.firmware
        before = s.taken_values
        fw.values["bus_voltage"] = 2**31 + 5  # (poked past the store's checks)
        _steps(env, 1)
        assert s.taken_values == before  # not the values path
        state = _joint(env).last_state
        assert state.raw.extra["bus_voltage"] == -(2**31) + 5  # the words' value
        last = _device_payloads(env)[-1]
        assert type(last) is mb.ReadRegistersReply
        assert state.raw.extra == s.decode(s.status_start, last.values)
        fw.values["bus_voltage"] = 48000
        _steps(env, 1)
        assert s.taken_values == before + 1  # back on the values path
    finally:
        env.close()


def test_a_reply_whose_registers_are_not_the_hosts_is_decoded_from_its_words() -> None:
    env = _env()
    try:
        _steps(env, 1)
        s = _stepper(env)
        shape = _shape(s)
        plan = shape.extra
        values = [7] * len(shape.registers)
        other = tuple(Register(r.address, r.name, "uint32" if r.type == "int32" else r.type) for r in shape.registers)
        before = s.taken_values
        for regs in (other, shape.registers[:-1]):
            reply = StatusReply(s.status, plan, values, regs)
            assert s._values(reply) == s.decode(s.status_start, reply.message().values)
        assert s.taken_values == before
        reply = StatusReply(s.status, plan, values, shape.registers)
        assert s._values(reply) == dict(zip(s._names, values))
        assert s.taken_values == before + 1
        assert reply.message() is reply.message()  # made once
        assert reply.message() == mb.ReadRegistersReply(s.status.slave, s.status.function,
                                                        ModbusFront.pack(plan, values, s.status.count))
    finally:
        env.close()


def test_a_replaced_reply_check_is_asked_after_the_exchange() -> None:
    """With a rule whose reply check is not the stock one, a lone read's reply is checked after (as the lane
    checks it), on the reply message, and the state is the same."""
    plain, checked = _env(), _env()
    try:
        s = _stepper(checked)
        rule = s.link.rule
        seen: list[Any] = []
        stock = rule.is_reply

        def is_reply(request: Any, reply: Any) -> bool:
            seen.append(type(reply))
            return bool(stock(request, reply))

        rule.is_reply = is_reply
        assert _steps(checked, 5) == _steps(plain, 5)
        assert mb.ReadRegistersReply in seen  # the lone read's reply, checked after, as the message
        assert s.lane.fused >= 15
    finally:
        plain.close()
        checked.close()


def test_the_replies_are_made_only_when_the_log_is_read() -> None:
    """The status replies of the line's log stay values through steps and a reset (a new timeline), and become
    the front's messages when the log is read."""
    env = _env()
    try:
        line = _joint(env).driver.access.link.transport

        def unmade() -> int:
            return sum(isinstance(p, StatusReply) and p._message is None for p in line._replies)  # the booked frames'

        _steps(env, 10)
        assert unmade() >= 10
        env.reset()
        _steps(env, 3)
        assert unmade() >= 13
        payloads = [tx.payload for tx in line.log if isinstance(tx.payload, mb.ReadRegistersReply)]
        assert unmade() == 0 and len(payloads) >= 13
    finally:
        env.close()


def test_a_read_planned_again_by_the_front_is_shaped_again() -> None:
    """The front's plans are a bounded cache: a status read planned again gets its shape (and proof) again and
    stays on the values path."""
    env = _env()
    try:
        _steps(env, 2)
        s = _stepper(env)
        old = _shape(s)
        before = s.taken_values
        s.exchange.front._read_plans.clear()
        _steps(env, 2)
        new = s.exchange._read[1]
        assert new is not old and new.extra is not old.extra and new.registers == old.registers
        assert s.taken_values == before + 2
    finally:
        env.close()
