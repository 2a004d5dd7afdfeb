"""``Param.check``'s fast path gives what ``check_value`` gives (value and type, or the same error text)."""

from __future__ import annotations

import math
from typing import Any

import pytest

from joints.devices.params import TYPES, Param, check_value
from joints.errors import CommandError

_BOUNDS = [(None, None), (-5, None), (None, 1000), (10, 20), (3, 3), (5, 4)]  # (5, 4): nothing passes


def _outcome(fn: Any, value: object) -> Any:
    try:
        got = fn(value)
    except CommandError as exc:
        return ("error", str(exc))
    return (type(got), got)


def _values(p: Param) -> list[object]:
    lo, hi = TYPES[p.type][0], TYPES[p.type][1]
    ends = {lo, hi, 0, 1, -1}
    for b in (p.minimum, p.maximum):
        if b is not None:
            ends |= {b - 1, b, b + 1}
    return [*sorted(ends), lo - 1, hi + 1, True, False, 1.0, 2.5, -3.0, math.nan, math.inf, "3", None, 10**30]


@pytest.mark.parametrize("type_", sorted(TYPES))
@pytest.mark.parametrize(("minimum", "maximum"), _BOUNDS)
def test_a_param_check_is_check_value(type_: str, minimum: int | None, maximum: int | None) -> None:
    p = Param("speed", type_, unit="rpm", minimum=minimum, maximum=maximum)
    for value in _values(p):
        want = _outcome(lambda v: check_value(p.name, p.type, v, p.minimum, p.maximum, p.unit), value)
        assert _outcome(p.check, value) == want, (type_, minimum, maximum, value)


def test_the_range_fields_stay_out_of_equality_and_repr() -> None:
    a, b = Param("x", "int16", minimum=-3), Param("x", "int16", minimum=-3)
    assert a == b and hash(a) == hash(b) and "_lo" not in repr(a)
    assert (a._lo, a._hi) == (-3, 0x7FFF)
