"""The eRob CAN custom protocol on the link: replies by node and shape, errors, late replies never answer."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import can
import pytest

from joints.clock import ManualClock
from joints.codecs import erob_can as ec
from joints.errors import DeviceRejected, FrameError, ReplyTimeout
from joints.link.base import Link, RetryPolicy
from joints.link.erob_can import FENCE_INDEX, ErobCanLink, ErobCanRule, OtherFrame, decode_host
from joints.transports.can import PythonCanTransport
from joints.transports.can_sim import CanMedium, LockstepCanBus

Answer = Callable[[ec.Request], Sequence[tuple[float, ec.Message | can.Message]]]


class Drive:
    """A scripted eRob on the medium: ``answer(request)`` gives (delay, reply) pairs; values by index."""

    def __init__(self, medium: CanMedium, answer: Answer | None = None) -> None:
        self.medium = medium
        self.answer = answer or self.plain
        self.node = medium.attach_peer(self, name="drive")
        self.values = {0x0002: 1000, 0x0020: 1, FENCE_INDEX: 0, 0x0008: 77}
        self.requests: list[ec.Request] = []

    def plain(self, req: ec.Request) -> Sequence[tuple[float, ec.Message | can.Message]]:
        if isinstance(req, ec.Read):
            return [(0.0, ec.ValueReply(req.node, self.values.get(req.index, 0)))]
        return [(0.0, ec.Ack(req.node))]

    def on_frame(self, frame: can.Message) -> Sequence[can.Message]:
        if ec.decoder_role(frame.arbitration_id) is not ec.Role.DEVICE:
            return []
        req = ec.decode(frame, ec.Role.DEVICE)
        assert isinstance(req, (ec.Read, ec.Write, ec.Command))
        self.requests.append(req)
        for delay, reply in self.answer(req):
            out = reply if isinstance(reply, can.Message) else ec.encode(reply)
            self.medium.send_at(self.node, out, self.medium.now + delay)
        return []


def make(answer: Answer | None = None, *, timeout: float = 0.1,
         retries: int = 0) -> tuple[ErobCanLink, Drive, ManualClock]:
    clock = ManualClock()
    medium = CanMedium(clock=clock)
    drive = Drive(medium, answer)
    link = ErobCanLink(PythonCanTransport(LockstepCanBus(medium=medium)), clock=clock,
                       policy=RetryPolicy(timeout=timeout, retries=retries),
                       error_text=lambda code: (f"text of {code:#x}", "hint"))
    return link, drive, clock


def test_read_write_and_command() -> None:
    link, drive, _ = make()
    reply = link.request(ec.Read(1, 0x0002), idempotent=True)
    assert reply == ec.ValueReply(1, 1000)
    assert link.request(ec.Write(1, 0x0087, 0)) == ec.Ack(1)
    assert link.request(ec.Command(1, 0x0083)) == ec.Ack(1)
    assert drive.requests == [ec.Read(1, 0x0002), ec.Write(1, 0x0087, 0), ec.Command(1, 0x0083)]


def test_error_reply_raises_device_rejected_with_the_manuals_code() -> None:
    link, _, _ = make(lambda req: [(0.0, ec.ErrorReply(req.node, 0x0027))])
    with pytest.raises(DeviceRejected, match="0x0027 text of 0x27") as info:
        link.request(ec.Command(1, 0x0083))
    assert info.value.code == 0x0027


def test_failed_read_raises_device_rejected() -> None:
    link, _, _ = make(lambda req: [(0.0, ec.ReadFailed(req.node))])
    with pytest.raises(DeviceRejected, match="0x80") as info:
        link.request(ec.Read(1, 0x0232, 2), idempotent=True)
    assert info.value.code == ec.READ_FAILED


def test_a_reply_of_another_node_is_unsolicited_and_never_the_answer() -> None:
    link, _, clock = make(lambda req: [(0.0, ec.ValueReply(req.node + 1, 5))])
    with pytest.raises(ReplyTimeout, match="node 1 did not answer on 0x5C1"):
        link.request(ec.Read(1, 0x0002), idempotent=True)
    assert [m for _, m in link.unsolicited] == [ec.ValueReply(2, 5)]
    assert clock.now() == pytest.approx(0.2, abs=1e-3)  # the timeout, then the late window


def test_frames_of_other_protocols_do_not_disturb_a_request() -> None:
    heartbeat = can.Message(arbitration_id=0x701, data=b"\x05", is_extended_id=False)
    link, _, _ = make(lambda req: [(0.0, heartbeat), (1e-4, ec.ValueReply(req.node, 9))])
    assert link.request(ec.Read(1, 0x0002), idempotent=True) == ec.ValueReply(1, 9)
    assert [type(m) for _, m in link.unsolicited] == [OtherFrame]
    assert "0x701" in repr(link.unsolicited[0][1])


def _enable_with_six_acks(req: ec.Request) -> list[tuple[float, ec.Message | can.Message]]:
    if isinstance(req, ec.Command) and req.index == 0x0100:
        return [(0.0, ec.Ack(req.node))] * 6  # figure 4-21: six 0x3E for one enable
    if isinstance(req, ec.Read):
        return [(0.0, ec.ValueReply(req.node, 0))]
    if isinstance(req, ec.Write) and req.value == 13:
        return [(0.0, ec.ErrorReply(req.node, 0x0015))]  # a write the drive refuses
    return [(0.0, ec.Ack(req.node))]


def test_extra_acks_of_enable_never_answer_the_next_write() -> None:
    link, drive, _ = make(_enable_with_six_acks)
    link.request(ec.Command(1, 0x0100, 1))
    # the next write is refused: if a stale 0x3E answered it, the refusal would go unnoticed
    with pytest.raises(DeviceRejected) as info:
        link.request(ec.Write(1, 0x0087, 13))
    assert info.value.code == 0x0015
    assert drive.requests == [ec.Command(1, 0x0100, 1), ec.Read(1, FENCE_INDEX), ec.Write(1, 0x0087, 13)]
    assert [m for _, m in link.unsolicited] == [ec.Ack(1)] * 5
    assert link.fences == 1
    link.request(ec.Write(1, 0x0087, 0))  # synchronised now: no second fence
    assert link.fences == 1


def test_without_the_fence_a_stale_ack_would_answer_the_write() -> None:
    """The hazard the fence removes, shown on a plain link with the same rule."""
    link, _, clock = make(_enable_with_six_acks)
    plain = Link(link.framing, ErobCanRule(), clock=clock, policy=RetryPolicy(timeout=0.1, retries=0))
    plain.request(ec.Command(1, 0x0100, 1))
    assert plain.request(ec.Write(1, 0x0087, 13)) == ec.Ack(1)  # wrongly accepted


def test_a_read_after_enable_is_its_own_fence() -> None:
    link, drive, _ = make(_enable_with_six_acks)
    link.request(ec.Command(1, 0x0100, 0))
    assert link.request(ec.Read(1, 0x0002), idempotent=True) == ec.ValueReply(1, 0)
    link.request(ec.Write(1, 0x0087, 0))
    assert link.fences == 0
    assert len(drive.requests) == 3


def test_a_late_reply_after_a_timeout_never_answers_the_next_read() -> None:
    calls = {"n": 0}

    def slow_first(req: ec.Request) -> list[tuple[float, ec.Message | can.Message]]:
        calls["n"] += 1
        assert isinstance(req, ec.Read)
        delay = 0.15 if calls["n"] == 1 else 0.0  # the first answer comes 50 ms after the timeout
        return [(delay, ec.ValueReply(req.node, req.index))]

    link, _, clock = make(slow_first)
    with pytest.raises(ReplyTimeout):
        link.request(ec.Read(1, 0x0002), idempotent=True)
    assert link.late_discarded == 1  # the late value arrived in the late window after the timeout
    assert clock.now() == pytest.approx(0.2, abs=1e-3)
    assert link.request(ec.Read(1, 0x0008), idempotent=True) == ec.ValueReply(1, 0x0008)


def test_a_retried_read_is_not_answered_by_its_own_late_first_reply() -> None:
    calls = {"n": 0}

    def slow_first(req: ec.Request) -> list[tuple[float, ec.Message | can.Message]]:
        calls["n"] += 1
        value = 100 * calls["n"]
        return [(0.15 if calls["n"] == 1 else 0.0, ec.ValueReply(req.node, value))]

    link, _, _ = make(slow_first, retries=2)
    assert link.request(ec.Read(1, 0x0002), idempotent=True) == ec.ValueReply(1, 200)
    assert link.retries_used == 1
    assert link.late_discarded == 1  # the late first answer was waited out, not taken for the retry's
    assert link.request(ec.Read(1, 0x0002), idempotent=True) == ec.ValueReply(1, 300)


def test_a_command_that_got_no_reply_has_an_unknown_outcome_and_the_next_write_is_fenced() -> None:
    from joints.errors import OutcomeUnknown

    calls = {"n": 0}

    def silent_then_late_ack(req: ec.Request) -> list[tuple[float, ec.Message | can.Message]]:
        calls["n"] += 1
        if calls["n"] == 1:
            return [(0.5, ec.Ack(req.node))]  # later than the timeout and the late window
        if isinstance(req, ec.Read):
            return [(0.0, ec.ValueReply(req.node, 0))]
        return [(0.0, ec.ErrorReply(req.node, 0x0016))]

    link, drive, clock = make(silent_then_late_ack, retries=2)
    with pytest.raises(OutcomeUnknown):
        link.request(ec.Command(1, 0x0083))
    assert len(drive.requests) == 1  # a command is never repeated blindly
    clock.advance(0.25)
    with pytest.raises(DeviceRejected):  # its own refusal, not the stale 0x3E
        link.request(ec.Write(1, 0x0087, 6), idempotent=True)
    assert drive.requests[1] == ec.Read(1, FENCE_INDEX)


def test_a_malformed_reply_is_a_frame_error_and_the_node_is_listened_to_before_the_next_request() -> None:
    bad = can.Message(arbitration_id=0x5C1, data=bytes([0, 0, 0, 1]), is_extended_id=False)  # no 0x3E
    calls = {"n": 0}

    def answer(req: ec.Request) -> list[tuple[float, ec.Message | can.Message]]:
        calls["n"] += 1
        return [(0.0, bad)] if calls["n"] == 1 else [(0.0, ec.ValueReply(req.node, 5))]

    link, _, _ = make(answer)
    with pytest.raises(FrameError):
        link.request(ec.Read(1, 0x0002), idempotent=True)
    assert link.request(ec.Read(1, 0x0002), idempotent=True) == ec.ValueReply(1, 5)


def test_commands_are_never_retried() -> None:
    link, drive, _ = make(lambda req: [], retries=3)
    with pytest.raises(ReplyTimeout):
        link.request(ec.Command(1, 0x0083))
    assert drive.requests == [ec.Command(1, 0x0083)]


def test_host_decoding_keeps_foreign_frames_apart() -> None:
    assert isinstance(decode_host(can.Message(arbitration_id=0x641, data=b"\x00\x02", is_extended_id=False)),
                      OtherFrame)  # another host's request (or our own echo)
    assert isinstance(decode_host(can.Message(arbitration_id=0x5C1, is_extended_id=True, data=b"\x3e")), OtherFrame)
    assert isinstance(decode_host(can.Message(arbitration_id=0x5C1, is_remote_frame=True, is_extended_id=False)),
                      OtherFrame)
    assert decode_host(can.Message(arbitration_id=0x5C1, data=b"\x3e", is_extended_id=False)) == ec.Ack(1)
    with pytest.raises(FrameError):
        decode_host(can.Message(arbitration_id=0x5C1, data=b"\x3f", is_extended_id=False))


def test_trace_shows_meaning() -> None:
    from joints.link.trace import Trace

    link, _, _ = make()
    trace = Trace()
    link.trace = trace
    link.request(ec.Read(1, 0x0005, 1), idempotent=True)
    text = [str(r) for r in trace]
    assert "node 1 read 0x0005/1" in text[0] and "node 1 value" in text[1]
