"""MksLink over a scripted drive: immediate replies by address + function, completion frames unsolicited,
send-only broadcast / group / long packets, respond off, refusals, retries only for reads."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from joints.clock import ManualClock
from joints.codecs import mks
from joints.errors import DeviceRejected, EncodeError, OutcomeUnknown, ReplyTimeout
from joints.link import RetryPolicy, Trace
from joints.link.mks import MksLink, MksRule, is_completion
from joints.transports.loopback import LoopbackTransport

FB = mks.encode


class Script:
    """A drive that answers each request with what ``answer`` returns (bytes), recording the requests."""

    def __init__(self, answer: Callable[[object], bytes]) -> None:
        self.answer = answer
        self.codec = mks.MksCodec(mks.Role.DEVICE)
        self.requests: list[object] = []

    def __call__(self, data: bytes) -> bytes:
        self.codec.feed(data)
        out = b""
        while (msg := self.codec.next_message()) is not None:
            self.requests.append(msg)
            out += self.answer(msg)
        return out


def link_to(answer: Callable[[object], bytes], *, retries: int = 2) -> tuple[MksLink, Script, ManualClock]:
    script = Script(answer)
    clock = ManualClock()
    link = MksLink(LoopbackTransport(script), clock=clock, policy=RetryPolicy(timeout=0.05, retries=retries))
    return link, script, clock


def test_reply_is_matched_by_address_and_function_completions_go_to_subscribers() -> None:
    def answer(msg: object) -> bytes:
        # a completion of another move and a late reply of another drive come first, then the reply
        return (FB(mks.RunReply(1, 0xFD, mks.RunStatus.COMPLETE)) + FB(mks.SpeedReply(2, 300))
                + FB(mks.SpeedReply(1, 120)))

    link, _script, _clock = link_to(answer)
    got: list[object] = []
    link.subscribe_completions(1, got.append)
    reply = link.request(mks.ReadSpeed(1), idempotent=True)
    assert reply == mks.SpeedReply(1, 120)
    assert got == [mks.RunReply(1, 0xFD, mks.RunStatus.COMPLETE)]  # the completion went to the subscriber
    assert [m for _t, m in link.unsolicited] == [mks.SpeedReply(2, 300)]  # nobody subscribed: kept
    assert link.retries_used == 0


def test_completion_of_the_same_function_is_never_the_reply() -> None:
    # the completion (status 2) of the previous 0xFD arrives before the new command's immediate reply
    frames = [FB(mks.RunReply(1, 0xFD, mks.RunStatus.COMPLETE)) + FB(mks.RunReply(1, 0xFD, mks.RunStatus.STARTED))]
    link, _s, _c = link_to(lambda m: frames.pop(0))
    trace = Trace()
    link.trace = trace
    reply = link.request(mks.RunRelativePulses(1, mks.RunDirection.CCW, 300, 2, 3200))
    assert reply == mks.RunReply(1, 0xFD, mks.RunStatus.STARTED)
    assert any("unsolicited" in r.meaning and "COMPLETE" in r.meaning for r in trace)
    assert is_completion(mks.RunReply(1, 0xFD, mks.RunStatus.END_LIMIT_STOP))
    assert is_completion(mks.CalibrationReply(1, mks.CalibrationStatus.SUCCESS))
    assert not is_completion(mks.CalibrationReply(1, mks.CalibrationStatus.CALIBRATING))


@pytest.mark.parametrize("request_", [
    mks.RunSpeed(0, mks.RunDirection.CCW, 100, 2),  # broadcast
    mks.LongPacket((mks.RunSpeed(1, mks.RunDirection.CCW, 100, 2), mks.RunSpeed(2, mks.RunDirection.CW, 50, 2))),
])
def test_broadcast_and_long_packets_are_send_only(request_: object) -> None:
    link, script, clock = link_to(lambda m: b"")
    assert link.request(request_) is None  # nothing waited for: no ReplyTimeout although nothing answers
    assert clock.now() == 0.0 and len(script.requests) == 1


def test_group_address_gets_no_reply_once_known() -> None:
    link, script, _c = link_to(lambda m: b"")
    with pytest.raises(EncodeError, match="no group address"):
        link.send_group(0x50, mks.RunSpeed(1, mks.RunDirection.CCW, 100, 2))
    assert script.requests == []  # refused before anything was sent
    link.note_group(1, 0x50)
    link.note_group(2, 0x50)
    link.send_group(0x50, mks.RunSpeed(1, mks.RunDirection.CCW, 100, 2))
    assert script.requests == [mks.RunSpeed(0x50, mks.RunDirection.CCW, 100, 2)]
    assert link.request(mks.RunSpeed(0x50, mks.RunDirection.CCW, 0, 0)) is None
    link.broadcast(mks.EmergencyStop(1))
    assert script.requests[-1] == mks.EmergencyStop(0)


def test_long_packet_refuses_repeated_slaves() -> None:
    link, script, _c = link_to(lambda m: b"")
    with pytest.raises(EncodeError, match="repeat"):
        link.send_long_packet([mks.EmergencyStop(1), mks.RunSpeed(1, mks.RunDirection.CW, 10, 0)])
    assert script.requests == []


def test_respond_off_silences_run_commands_but_not_queries() -> None:
    def answer(msg: object) -> bytes:
        if isinstance(msg, mks.QueryStatus):
            return FB(mks.MotorStatusReply(3, mks.MotorStatus.FULL_SPEED))
        return b""  # respond off: the drive executes run commands silently

    link, _script, clock = link_to(answer)
    link.note_respond(3, False)
    assert link.request(mks.RunSpeed(3, mks.RunDirection.CCW, 500, 10)) is None
    assert clock.now() == 0.0
    assert link.request(mks.QueryStatus(3), idempotent=True) == mks.MotorStatusReply(3, mks.MotorStatus.FULL_SPEED)
    rule = link.rule
    assert isinstance(rule, MksRule)
    assert rule.expects_reply(mks.SetWorkingCurrent(3, 1000))  # settings still answer
    assert rule.expects_reply(mks.GoHome(3))  # go home is no Part 6 run command
    link.note_respond(3, True)
    assert rule.expects_reply(mks.RunSpeed(3, mks.RunDirection.CCW, 500, 10))


def test_status_zero_is_the_drives_refusal() -> None:
    link, _s, _c = link_to(lambda m: FB(mks.RunReply(1, 0xF6, mks.RunStatus.FAIL)))
    with pytest.raises(DeviceRejected, match="status 0") as info:
        link.request(mks.RunSpeed(1, mks.RunDirection.CCW, 100, 2))
    assert info.value.function == 0xF6
    link2, _s2, _c2 = link_to(lambda m: FB(mks.SetReply(1, 0x83, mks.SetStatus.FAIL)))
    with pytest.raises(DeviceRejected):
        link2.request(mks.SetWorkingCurrent(1, 9000), idempotent=True)


def test_reads_are_retried_after_a_corrupt_reply_run_commands_never() -> None:
    good = FB(mks.SpeedReply(1, 42))
    answers = [good[:-1] + bytes((good[-1] ^ 1,)), good]
    link, script, _c = link_to(lambda m: answers.pop(0))
    assert link.request(mks.ReadSpeed(1), idempotent=True) == mks.SpeedReply(1, 42)
    assert len(script.requests) == 2 and link.retries_used == 1

    link2, script2, _c2 = link_to(lambda m: b"")  # the reply to a run command is lost
    with pytest.raises(OutcomeUnknown, match="may have executed"):
        link2.request(mks.RunAbsoluteAxis(1, 600, 2, 0x4000))
    assert len(script2.requests) == 1  # sent once
    with pytest.raises(ReplyTimeout):
        link2.request(mks.ReadSpeed(1), idempotent=True)
    assert len(script2.requests) == 4  # a read: 1 + 2 retries


def test_a_host_does_not_send_replies() -> None:
    link, script, _c = link_to(lambda m: b"")
    with pytest.raises(EncodeError):
        link.request(mks.SpeedReply(1, 1))
    assert script.requests == []
