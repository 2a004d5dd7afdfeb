"""A python-can bus that never hands its owner the echoes of its own frames.

Rule: a wrapper around any python-can bus, no decoding. python-can's ``udp_multicast`` interface
(where ``joints sim serve`` puts simulated CAN buses) returns every frame to its sender through
multicast loopback, unmarked (``is_rx`` True), which no real CAN controller does. A program that
takes its own frames for another node's may misbehave: canopen's ``PdoMap`` takes the echo of an
RPDO it sent for a received one, infers a period from two of them and from then on only updates
the RPDO's value instead of sending it (a ``BaseNode402`` then stops sending controlwords).
:class:`EchoFreeBus` drops those echoes (:class:`~joints.transports.can.EchoFilter`), so any
python-can program joins a served bus as it would a real one::

    bus = EchoFreeBus(can.Bus(interface="udp_multicast", channel=group, port=udp_port, hop_limit=0))
    network = canopen.Network(bus).connect()

Imported only where a CAN bus is used (it imports python-can at its top).
"""

from __future__ import annotations

from typing import Any

import can

from joints.transports.can import EchoFilter

__all__ = ["EchoFreeBus"]


class EchoFreeBus(can.BusABC):
    """``bus`` without the echoes of the frames sent through this wrapper (see the module docstring)."""

    def __init__(self, bus: can.BusABC, **kwargs: Any) -> None:
        self.inner = bus
        self.echoes = EchoFilter()
        self.channel_info = f"{getattr(bus, 'channel_info', type(bus).__name__)} (echoes dropped)"
        self._can_protocol = getattr(bus, "_can_protocol", can.CanProtocol.CAN_20)
        super().__init__(channel=getattr(bus, "channel", "") or "", **kwargs)

    @property
    def echoes_dropped(self) -> int:
        return self.echoes.dropped

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.echoes.sent(msg)  # before it goes: the echo may come back before send returns
        try:
            self.inner.send(msg, timeout)
        except BaseException:
            self.echoes.unsent(msg)
            raise

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        msg = self.inner.recv(timeout)
        if msg is None or self.echoes.is_echo(msg):
            return None, False  # BusABC.recv asks again while its timeout lasts
        return msg, False

    def fileno(self) -> int:
        return int(self.inner.fileno())

    def shutdown(self) -> None:
        if not self._is_shutdown:
            self.inner.shutdown()
        super().shutdown()
