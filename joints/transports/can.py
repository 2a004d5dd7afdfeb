"""CAN frame transports: python-can's ``Bus`` of any interface behind one small ABC.

Rule: frames only (python-can's :class:`can.Message`; no frame class of our own), no decoding,
no retries. ``recv(timeout)`` waits at most ``timeout`` seconds and returns one frame or None.
Hardware and served channels are python-can buses chosen by config (``interface``, ``channel``,
``bitrate`` and the interface's own keywords, e.g. ``port`` of udp_multicast); the sim's
in-process bus is a python-can bus too, so the same wrapper serves every case.
"""

from __future__ import annotations

import abc
import threading
import time
from collections import deque
from types import TracebackType
from typing import Any

from joints.errors import ConfigError, MissingDependencyError, TransportError


def python_can() -> Any:
    try:
        import can
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise MissingDependencyError("python-can", "can") from exc
    return can


class FrameTransport(abc.ABC):
    """A bidirectional stream of CAN frames."""

    @abc.abstractmethod
    def send(self, frame: Any) -> None:
        """Send one ``can.Message``."""

    @abc.abstractmethod
    def recv(self, timeout: float) -> Any | None:
        """The next received ``can.Message``, waiting up to ``timeout`` s; None if none arrived."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the bus. Idempotent."""

    @property
    def name(self) -> str:
        return type(self).__name__

    def __enter__(self) -> FrameTransport:  # noqa: PYI034 - typing.Self needs Python 3.11
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


class EchoFilter:
    """Recognises the echoes of frames one sender sent (udp_multicast returns each frame to its sender, unmarked).

    :meth:`sent` before the frame goes out (an echo can come back before ``send`` returns in another
    thread), :meth:`is_echo` for each received frame: a frame equal to one sent and not yet seen
    back is taken for its echo. Echoes come back in order, so older unmatched frames were lost on
    the way back and are forgotten. Thread-safe (a receiving thread and a sending one).
    """

    #: sent frames remembered (older ones were lost on the way back)
    WINDOW = 256

    def __init__(self, window: int = WINDOW) -> None:
        self._sent: deque[tuple[int, bool, bytes]] = deque(maxlen=window)
        self._lock = threading.Lock()
        self.dropped = 0  #: echoes recognised

    def sent(self, frame: Any) -> None:
        with self._lock:
            self._sent.append(_key(frame))

    def unsent(self, frame: Any) -> None:
        """The frame did not go out after all (its send failed): no echo is coming."""
        key = _key(frame)
        with self._lock:
            for i in range(len(self._sent) - 1, -1, -1):
                if self._sent[i] == key:
                    del self._sent[i]
                    return

    def is_echo(self, frame: Any) -> bool:
        key = _key(frame)
        with self._lock:
            sent = self._sent
            if not sent or key not in sent:
                return False
            while sent.popleft() != key:
                pass
            self.dropped += 1
            return True


class PythonCanTransport(FrameTransport):
    """Any python-can bus (socketcan, pcan, kvaser, slcan, virtual, udp_multicast, the sim's lockstep bus).

    ``ignore_own`` drops frames this bus sent itself that come back to it, marked as its own
    (``is_rx`` False). ``echoes``: the bus returns every frame to its sender unmarked
    (udp_multicast does: multicast loopback), so each received frame equal to one sent and not yet
    seen back is taken for that echo and dropped (a real controller never echoes).
    """

    def __init__(self, bus: Any, *, ignore_own: bool = True, echoes: bool = False) -> None:
        self.bus = bus
        self.ignore_own = ignore_own
        self.echoes = echoes
        self._echo = EchoFilter()
        self._closed = False

    @property
    def echoes_dropped(self) -> int:
        """Echoes of our own frames recognised and dropped."""
        return self._echo.dropped

    @classmethod
    def open(cls, interface: str, channel: str | int | None, bitrate: int | None = None, **kwargs: Any) -> PythonCanTransport:
        """Open ``can.Bus(interface=..., channel=..., bitrate=..., **kwargs)`` with a clear error if it fails."""
        can = python_can()
        if bitrate is not None:
            kwargs["bitrate"] = bitrate
        echoes = interface == "udp_multicast"
        if echoes:
            kwargs.setdefault("hop_limit", 0)  # simulated frames never leave this host
            kwargs.pop("bitrate", None)  # a multicast group has no bit rate
        try:
            bus = can.Bus(interface=interface, channel=channel, **kwargs)
        except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
            raise TransportError(
                f"cannot open CAN bus interface={interface!r} channel={channel!r}: {exc}. Check the interface name "
                "(python -m can.viewer), that the adapter is connected and up (ip link set can0 up type can "
                "bitrate 1000000), and that no other program holds it exclusively."
            ) from exc
        except TypeError as exc:
            raise ConfigError(f"CAN interface {interface!r} does not take these settings: {exc}", key="interface") from exc
        return cls(bus, echoes=echoes)

    @property
    def name(self) -> str:
        return f"can:{getattr(self.bus, 'channel_info', type(self.bus).__name__)}"

    def send(self, frame: Any) -> None:
        if self._closed:
            raise TransportError(f"{self.name} is closed")
        if self.echoes:
            self._echo.sent(frame)
        try:
            self.bus.send(frame)
        except Exception as exc:
            if self.echoes:
                self._echo.unsent(frame)
            raise TransportError(f"send on {self.name} failed: {exc}") from exc

    def recv(self, timeout: float) -> Any | None:
        if self._closed:
            raise TransportError(f"{self.name} is closed")
        deadline = time.monotonic() + max(timeout, 0.0)
        try:
            while True:
                frame = self.bus.recv(timeout=max(timeout, 0.0))
                if frame is None:
                    return None
                if ((self.ignore_own and getattr(frame, "is_rx", True) is False)
                        or (self.echoes and self._echo.is_echo(frame))):
                    timeout = deadline - time.monotonic()  # our own frame came back: wait out the rest
                    continue
                return frame
        except Exception as exc:
            raise TransportError(f"receive on {self.name} failed: {exc}") from exc

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.bus.shutdown()


def _key(frame: Any) -> tuple[int, bool, bytes]:
    return (frame.arbitration_id, bool(frame.is_extended_id), bytes(frame.data))
