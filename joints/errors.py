"""The one exception tree of ``joints``.

Rule: every error says what was expected and what came, and (where it helps) what to do.
Protocol errors are split by blame: :class:`RequestError` (we asked for something illegal,
or the device told us so) versus :class:`PeerProtocolError` (the peer sent something broken).
"""

from __future__ import annotations

import enum
from collections.abc import Iterable


class JointsError(Exception):
    """Root of every error raised by ``joints``."""


# --- configuration ---------------------------------------------------------------------------


class ConfigError(JointsError, ValueError):
    """A configuration value is missing or not allowed.

    The message names the file, the key and what is allowed.
    """

    def __init__(
        self,
        message: str,
        *,
        file: str | None = None,
        key: str | None = None,
        allowed: Iterable[object] | str | None = None,
    ) -> None:
        self.message = message  #: the bare message, without file/key/allowed (for re-raising)
        self.file = file
        self.key = key
        # keep a one-shot iterable usable after the message consumed it
        self.allowed = allowed if allowed is None or isinstance(allowed, str) else tuple(allowed)
        allowed = self.allowed
        where = ""
        if file:
            where += f"{file}: "
        if key:
            where += f"[{key}] "
        text = where + message
        if allowed is not None:
            if isinstance(allowed, str):
                text += f" (allowed: {allowed})"
            else:
                text += " (allowed: " + ", ".join(repr(a) for a in allowed) + ")"
        super().__init__(text)


class MissingDependencyError(JointsError, ImportError):
    """An optional dependency is not installed; the message names the extra to install."""

    def __init__(self, module: str, extra: str) -> None:
        super().__init__(
            f"{module!r} is required for this feature but is not installed; "
            f"install it with: pip install 'joints[{extra}]'"
        )
        self.name = module


# --- protocol --------------------------------------------------------------------------------


class ProtocolError(JointsError):
    """Something on the wire was not what the protocol allows."""


class RequestError(ProtocolError):
    """Our side is to blame: a request that is illegal, or one the device refused."""


class EncodeError(RequestError, ValueError):
    """A message cannot be encoded (a field is out of its protocol range); nothing was sent."""


class DeviceRejected(RequestError):
    """The device answered with a protocol exception (e.g. Modbus exception reply)."""

    def __init__(self, message: str, *, code: int, function: int | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.function = function


class PeerProtocolError(ProtocolError):
    """The peer is to blame: a malformed, corrupted or unexpected frame."""


class FrameError(PeerProtocolError):
    """Bytes that do not form a valid frame (bad structure, garbage)."""

    def __init__(self, message: str, *, data: bytes = b"") -> None:
        super().__init__(message)
        self.data = data


class ChecksumError(FrameError):
    """A frame whose CRC/checksum does not match its content."""


class ByteCountError(FrameError):
    """A frame whose byte-count field disagrees with its data or with the request."""


class UnexpectedReply(PeerProtocolError):
    """A well-formed reply that does not answer our request (other slave, function, address)."""


# --- devices ---------------------------------------------------------------------------------


class DeviceFault(JointsError):
    """The drive reports a fault: carries the device's own code, its name and the manual's text for it."""

    def __init__(self, device: str, code: int, text: str, *, hint: str = "", name: str = "") -> None:
        self.device = device
        self.code = code
        self.text = text
        self.hint = hint
        self.name = name
        label = f"{name} (0x{code:04X})" if name and code < 0x10000 else name or f"0x{code:04X} ({code})"
        msg = f"{device}: fault {label}: {text}"
        if hint:
            msg += f" - to clear: {hint}"
        super().__init__(msg)


class RegisterError(JointsError, KeyError):
    """An unknown register name/address, or an access the register does not allow."""

    def __str__(self) -> str:  # KeyError would repr() the message
        return str(self.args[0]) if self.args else ""


class UnknownJoint(JointsError, KeyError):
    """A joint name the rig does not have; the message lists the ones it has."""

    def __str__(self) -> str:  # KeyError would repr() the message
        return str(self.args[0]) if self.args else ""


class CommandError(JointsError, ValueError):
    """A command that is out of range or not allowed in the current state; nothing was sent."""


class LimitError(CommandError):
    """A command outside the joint's configured limits; nothing was sent (names the joint, value and limit)."""


class MotionTimeout(JointsError, TimeoutError):
    """A joint did not reach its goal (stop moving, a condition) within the time allowed.

    Not a :class:`TransportError`: the bus worked, the motion took too long.
    """


class Refusal(enum.Enum):
    """Why a (simulated) drive refuses a parameter access, whatever the protocol that asked.

    Each protocol front maps it to its own answer (a Modbus exception code, a CAN error code, an
    SDO abort code).
    """

    UNKNOWN = "unknown parameter"
    NOT_READABLE = "not readable"
    NOT_WRITABLE = "not writable"
    OUT_OF_RANGE = "value out of range"
    STATE = "refused in this state"


class ParameterRefused(JointsError):
    """A drive's firmware refuses a read or write of one of its parameters (device side, sim)."""

    def __init__(self, reason: Refusal, name: str, detail: str = "") -> None:
        self.reason = reason
        self.name = name
        super().__init__(f"{name}: {reason.value}" + (f" ({detail})" if detail else ""))


class StateError(JointsError):
    """The joint or drive is not in a state that allows the request (e.g. not enabled)."""


class ConfirmationRequired(JointsError):
    """A persistent or dangerous write was asked for without the explicit confirmation argument."""


# --- transports ------------------------------------------------------------------------------


class TransportError(JointsError):
    """The bus or port failed (cannot open, closed, I/O error)."""


class ReplyTimeout(TransportError, TimeoutError):
    """No (complete) reply arrived within the timeout."""


class OutcomeUnknown(ReplyTimeout):
    """A write got no reply: the drive may have executed it or not (a valid frame can arrive late).

    The link never re-sends such a write blindly; read back what matters before acting again.
    """


class OverrunError(JointsError):
    """A fixed-rate step ran over its control period (raised only where asked: ``raise_on_overrun=True``)."""
