"""MKS native framing: silence is silence (found by the reliability harness, issue 18).

``feed(b"")`` after ``flush()`` reported new bytes and cleared the silence, so a device bus whose
``silence()`` flushes and then feeds nothing kept a frame cut short buffered, to be completed by
the next frame's bytes.
"""

from __future__ import annotations

import pytest

from joints.codecs import mks
from joints.codecs.mks import Role
from joints.errors import FrameError


@pytest.mark.parametrize("role,head", [(Role.DEVICE, "FA 01 F6 01"), (Role.HOST, "FB 01 30 00")])
def test_feeding_nothing_after_silence_keeps_the_line_silent(role: Role, head: str) -> None:
    codec = mks.MksCodec(role)
    codec.feed(bytes.fromhex(head))  # a frame that stopped half-way
    assert codec.next_message() is None
    codec.flush()
    codec.feed(b"")
    with pytest.raises(FrameError, match="truncated"):
        codec.next_message()  # truncated: dropped at silence
    assert codec.buffered == 0
