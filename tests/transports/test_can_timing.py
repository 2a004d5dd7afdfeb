"""Wire time of classic CAN frames: field counts, worst-case stuffing bound, exact stuffing."""

from __future__ import annotations

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from joints.transports.can_timing import frame_bits, frame_time, stuff_bits, unstuffed_bits


def _frame(ident: int, data: bytes, *, extended: bool = False) -> can.Message:
    return can.Message(arbitration_id=ident, data=data, is_extended_id=extended)


@pytest.mark.parametrize("n,bits", [(0, 47), (2, 63), (4, 79), (5, 87), (8, 111)])
def test_unstuffed_standard_frame_is_47_plus_8n(n: int, bits: int) -> None:
    assert unstuffed_bits(_frame(0x641, bytes(n))) == bits


def test_unstuffed_extended_frame_is_67_plus_8n() -> None:
    assert unstuffed_bits(_frame(0x1234567, bytes(8), extended=True)) == 131


@pytest.mark.parametrize("n,worst", [(0, 8), (2, 12), (4, 16), (5, 18), (6, 20), (8, 24)])
def test_worst_case_stuff_bits(n: int, worst: int) -> None:
    assert stuff_bits(_frame(0x641, bytes(n))) == worst


def test_eight_byte_worst_case_is_the_textbook_135_bits() -> None:
    assert frame_bits(_frame(0x7FF, bytes(8))) == 135  # Davis et al. 2007: 55 + 10n for standard ids
    assert frame_bits(_frame(0x7FF, bytes(8)), "none") == 111


def test_all_zero_frame_stuffs_after_every_five_equal_bits() -> None:
    # id 0, DLC 0: SOF + 11 id + RTR + IDE + r0 + DLC(4) = 19 dominant bits, then the CRC of zeros (0):
    # 34 dominant bits, a recessive stuff bit after each 5 of them
    f = can.Message(arbitration_id=0, data=b"", is_extended_id=False)
    assert stuff_bits(f, exact=True) == 34 // 5



@given(ident=st.integers(0, 0x7FF), data=st.binary(max_size=8))
def test_exact_stuffing_never_exceeds_the_bound(ident: int, data: bytes) -> None:
    f = _frame(ident, data)
    assert 0 <= stuff_bits(f, exact=True) <= stuff_bits(f)
    assert frame_bits(f, "none") <= frame_bits(f, "exact") <= frame_bits(f, "worst")


@given(ident=st.integers(0, 0x1FFFFFFF), data=st.binary(max_size=8))
def test_exact_stuffing_of_extended_frames_never_exceeds_the_bound(ident: int, data: bytes) -> None:
    f = _frame(ident, data, extended=True)
    assert 0 <= stuff_bits(f, exact=True) <= stuff_bits(f)


def test_frame_time_at_one_megabit() -> None:
    assert frame_time(_frame(0x641, bytes(2)), 1_000_000) == pytest.approx(75e-6)
    assert frame_time(_frame(0x5C1, bytes(5)), 500_000, "none") == pytest.approx(174e-6)


def test_unknown_stuffing_model_is_refused() -> None:
    with pytest.raises(ValueError, match="stuffing"):
        frame_bits(_frame(1, b""), "average")
