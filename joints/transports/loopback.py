"""In-process loopback transport: the host's bytes go straight into a device object.

Rule: synchronous and deterministic. A write hands the bytes to the peer at once and queues its
answer; a read returns what is queued or ``b""`` at once (nothing else can arrive in process, so
an empty read is a timeout that cost no wall-clock time). A peer that sends frames by itself (an
:class:`UnsolicitedPeer`, e.g. MKS drives' completion frames) is asked for them on every read.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, runtime_checkable

from joints.errors import TransportError
from joints.transports.base import ByteTransport


class BytePeer(Protocol):
    """What sits on the other end: receives bytes, returns the bytes it sends back."""

    def receive(self, data: bytes) -> bytes: ...


@runtime_checkable
class UnsolicitedPeer(Protocol):
    """A peer that also sends frames nobody asked for (completion frames on the simulated clock)."""

    def take_unsolicited(self) -> bytes:
        """The bytes it sent by itself since the last call (oldest first)."""
        ...


class LoopbackTransport(ByteTransport):
    """Connects a host-side link to an in-process :class:`BytePeer` (emulator, scripted slave)."""

    def __init__(self, peer: BytePeer | Callable[[bytes], bytes] | None = None, *, echo: bool = False) -> None:
        self._peer = peer
        self._rx = bytearray()
        self._closed = False
        self.echo = echo  #: mimic an RS485 adapter that hears its own transmission
        self.tx_bytes = 0
        self.rx_bytes = 0

    def attach(self, peer: BytePeer | Callable[[bytes], bytes] | None) -> None:
        self._peer = peer

    def inject(self, data: bytes) -> None:
        """Queue bytes as if the peer had sent them (tests: noise, unsolicited frames)."""
        self._rx += data

    def write(self, data: bytes) -> None:
        if self._closed:
            raise TransportError("loopback transport is closed")
        self.tx_bytes += len(data)
        if self.echo:
            self._rx += data
        peer = self._peer
        if peer is None:
            return
        receive = getattr(peer, "receive", None)
        answer = receive(bytes(data)) if receive is not None else peer(bytes(data))  # type: ignore[operator]
        if answer:
            self._rx += answer

    def read(self, timeout: float) -> bytes:
        if self._closed:
            raise TransportError("loopback transport is closed")
        peer = self._peer
        if isinstance(peer, UnsolicitedPeer):
            self._rx += peer.take_unsolicited()
        data = bytes(self._rx)
        self._rx.clear()
        self.rx_bytes += len(data)
        return data

    def reset_input(self) -> None:
        self._rx.clear()

    def close(self) -> None:
        self._closed = True
