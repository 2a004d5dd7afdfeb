"""The direct lane: a link's request to an in-process twin over an idle timed line, in one function.

Rule: it gives what :meth:`~joints.link.base.Link.request` gives - the same counts, simulated frame
instants, clock calls, reply validation (``as_received`` + the rule's ``is_reply``), errors, retries -
and only skips the layers between (the link's attempt, the direct framing's ``_timed``, the line's
``transact``). It takes a request only where nothing is in flight and nothing watches: no trace, no
reply queued, nothing pending on a :class:`~joints.transports.serial_sim.TimedSerialLine` whose peer
acts only on host frames, a Modbus request that is not a write of 0xFFFF (whose answer a slave with
failure replies makes ambiguous); anything else goes to ``link.request`` before anything is sent. A
reply that is not the plain answer (silence, a frame the host refuses, another slave's reply) continues
as the link's own attempt does (:meth:`Link._await_reply`, then the link's retries,
:meth:`Link._attempts`). tests/sim/test_compiled_path.py proves both equal to the link's path.
"""

from __future__ import annotations

import functools
from typing import Any

from joints.errors import FrameError, PeerProtocolError, ReplyTimeout
from joints.link.base import DirectFraming, Link
from joints.link.modbus import FAILED_VALUE, _single_write
from joints.transports.serial_sim import TimedSerialLine

__all__ = ["LinkLane"]


class LinkLane:
    """A link's requests on the direct lane where it can take them (see the module docstring)."""

    def __init__(self, link: Link[Any]) -> None:
        self.link = link
        framing = link.framing
        self.framing = framing if isinstance(framing, DirectFraming) else None
        line = getattr(framing, "transport", None)
        self.line = line if isinstance(line, TimedSerialLine) else None
        self.taken = 0  #: requests that took the lane

    def _open(self, request: Any) -> bool:
        """Whether the lane can take ``request`` now (nothing sent yet either way)."""
        link, framing, line = self.link, self.framing, self.line
        if framing is None or line is None or link.trace is not None or link._direct is not framing:
            return False
        if framing._line is not line or framing.pending() or line._pending or line._cap is not None or line._closed:
            return False
        if not link.rule.expects_reply(request) or _single_write(request) == FAILED_VALUE:
            return False
        return bool(line._plain_peer())

    def request(self, request: Any, *, idempotent: bool = False) -> Any:
        """:meth:`Link.request` of ``request`` (a Modbus request)."""
        if not self._open(request):
            return self.link.request(request, idempotent=idempotent)
        link = self.link
        framing = self.framing
        line = self.line
        assert framing is not None and line is not None
        rule = link.rule
        rule.check(request)  # raises EncodeError before anything is sent
        with link._lock:
            link.transactions += 1
            deadline = link.clock.now() + link.policy.timeout  # from the request's start, as the link's
            framing.exchanges += 1
            size = framing.size
            raw = line._transact_idle(line._sync(), size(request), functools.partial(framing.peer.exchange, request),
                                      size, framing._turnaround(request))
            reply = None if raw is None else framing.as_received(request, raw)
            try:  # as the link's attempt: a reply the rule refuses (another slave's) fails the attempt
                if reply is not None and not isinstance(reply, FrameError) and rule.is_reply(request, reply):
                    self.taken += 1
                    return reply
                framing.put(reply)  # not the plain answer: the rest of the attempt and the retries are the link's
                return link._await_reply(request, deadline)
            except (ReplyTimeout, PeerProtocolError) as exc:
                link._discard_late()
                return link._attempts(request, None, idempotent, failed=exc)
