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
:meth:`Link._attempts`). :meth:`LinkLane.exchange` hands several requests to a twin's one-call exchange (the
sim's eRob, :mod:`joints.sim.erob_exchange`) under the same conditions, or sends nothing.
tests/sim/test_compiled_path.py proves both equal to the link's path.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Any

from joints.codecs import modbus as mb
from joints.errors import FrameError, PeerProtocolError, ReplyTimeout
from joints.link.base import DirectFraming, Link
from joints.link.modbus import FAILED_VALUE, ModbusRule, _single_write
from joints.transports.serial_sim import Deferred, TimedSerialLine

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
        self.fused = 0  #: of them, requests sent by a twin's one-call exchange (:meth:`exchange`)
        #: the stock reply check (one bound method, the same object every call: a one-call exchange may keep a
        #: read's answer by it, :meth:`exchange`)
        self._stock_check = self._plain_reply

    def _open(self, request: Any) -> bool:
        """Whether the lane can take ``request`` now (nothing sent yet either way)."""
        return self._idle() and self._plain(request)

    def _idle(self) -> bool:
        """Whether the link and its line are as the lane needs them: nothing traced, in flight or pending."""
        link, framing, line = self.link, self.framing, self.line
        if framing is None or line is None or link.trace is not None or link._direct is not framing:
            return False
        if framing._line is not line or framing.pending() or line._pending or line._cap is not None or line._closed:
            return False
        return bool(line._plain_peer())

    def _plain(self, request: Any) -> bool:
        """Whether ``request`` gets a reply whose meaning the lane can take (not an FC06 write of 0xFFFF)."""
        return bool(self.link.rule.expects_reply(request)) and _single_write(request) != FAILED_VALUE

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
            return self._finish(request, raw, deadline, idempotent)

    def _finish(self, request: Any, raw: Any, deadline: float, idempotent: bool) -> Any:
        """The rest of the link's attempt once the peer's reply ``raw`` (None: silence) reached the host."""
        link, framing = self.link, self.framing
        assert framing is not None
        reply = None if raw is None else framing.as_received(request, raw)
        try:  # as the link's attempt: a reply the rule refuses (another slave's) fails the attempt
            if reply is not None and not isinstance(reply, FrameError) and link.rule.is_reply(request, reply):
                self.taken += 1
                return reply
            framing.put(reply)  # not the plain answer: the rest of the attempt and the retries are the link's
            return link._await_reply(request, deadline)
        except (ReplyTimeout, PeerProtocolError) as exc:
            link._discard_late()
            return link._attempts(request, None, idempotent, failed=exc)

    def _plain_reply(self, request: Any, reply: Any) -> bool:
        """Whether the host takes ``reply`` as the plain answer to ``request`` (``as_received`` + ``is_reply``)."""
        framing = self.framing
        assert framing is not None
        return framing.as_received(request, reply) is reply and bool(self.link.rule.is_reply(request, reply))

    def _stock(self) -> bool:
        """Whether the reply check is the Modbus codec's and rule's own (``mb.as_received``,
        ``ModbusRule.is_reply``): a plain request's (:meth:`_plain`) own reply - a read's with its words plain, a
        write's echo - it takes for the plain answer by the request's kind, slave, address and size alone
        (never a failure reply: its value is not 0xFFFF, its count not 0), so it can be asked before anything
        is sent, and its answer kept per request shape (:meth:`_stock_check` is the same object every call)."""
        framing = self.framing
        return framing is not None and framing.as_received is mb.as_received and getattr(
            self.link.rule.is_reply, "__func__", None) is ModbusRule.is_reply

    def ready(self, requests: Sequence[Any]) -> bool:
        """Whether :meth:`exchange` may hand ``requests`` to a one-call exchange now: the lane idle (:meth:`_idle`)
        and every request plain (:meth:`_plain`); each is then checked by the rule, which raises
        :class:`~joints.errors.EncodeError` before anything is sent."""
        if self.framing is None or not self._idle():
            return False
        rule = self.link.rule
        expects = rule.expects_reply
        for r in requests:  # _plain of each (nothing sent where one is not)
            if not expects(r) or _single_write(r) == FAILED_VALUE:
                return False
        for r in requests:
            rule.check(r)
        return True

    def count_fused(self, n: int, *, plain: bool) -> None:
        """``n`` requests a one-call exchange sent, counted as the link counts them (``plain``: their replies
        were checked before anything was sent, so they took the lane)."""
        framing = self.framing
        assert framing is not None
        self.link.transactions += n
        framing.exchanges += n
        self.fused += n
        if plain:
            self.taken += n

    def exchange(self, run: Callable[..., list[Any] | None], requests: Sequence[Any], *,
                 idempotent: bool = False) -> list[Any] | None:
        """:meth:`request` of each of ``requests`` by ``run(requests, size, check)``, a twin's one-call exchange
        (the frames, the physics between them and the drives' ops in one compiled call, e.g.
        :meth:`joints.sim.erob_exchange.ErobExchange.run`: ``check(request, reply)`` tells it before anything is
        sent whether the host takes a reply as the plain answer - with the stock check (:meth:`_stock`) for
        every request, else for several, and None for a lone request, whose reply is then checked after, as
        :meth:`request` checks it - ``size`` a message's characters); None where the lane or the exchange
        cannot take them all (nothing sent: send them the usual way). A reply may be a
        :class:`~joints.transports.serial_sim.Deferred` one (its message made when asked), where ``run`` gives
        one. ``idempotent``: a lone request's, for the rest of its attempt where its reply is not the plain
        answer."""
        framing = self.framing
        if framing is None or not self.ready(requests):
            return None
        link = self.link
        rule = link.rule
        n = len(requests)
        check: Callable[[Any, Any], bool] | None = None
        if self._stock():  # every reply checked before anything is sent
            check = self._stock_check
        elif n > 1:  # several replies are checked before anything is sent
            as_received = framing.as_received

            def plain(request: Any, reply: Any) -> bool:
                return as_received(request, reply) is reply and bool(rule.is_reply(request, reply))

            check = plain

        with link._lock:
            if check is not None:
                replies = run(requests, framing.size, check)
                if replies is None:
                    return None
                self.count_fused(n, plain=True)  # their replies were checked before anything was sent: plain
                return replies
            deadline = link.clock.now() + link.policy.timeout  # the request's, as the link's
            # a lone request's reply is checked after, as the lane checks it
            replies = run(requests, framing.size, None)
            if replies is None:
                return None
            self.count_fused(1, plain=False)
            raw = replies[0]
            replies[0] = self._finish(requests[0], raw.message() if isinstance(raw, Deferred) else raw, deadline,
                                      idempotent)
            return replies
