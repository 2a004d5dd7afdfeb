"""Transports: the only I/O. One small ABC per kind of bus (byte stream here; CAN frames wrap python-can)."""

from joints.transports.base import ByteTransport
from joints.transports.loopback import LoopbackTransport

__all__ = ["ByteTransport", "LoopbackTransport"]
