"""RS485 local echo: the bytes an adapter hands back of what the host itself just sent.

Rule: a stream codec that was told ``expect_echo(frame)`` skips that exact frame once, and only
when the input starts with it. A partial echo waits for its rest while the line is busy; after
silence (or when the input differs) the bytes are frames like any other.
"""

from __future__ import annotations


def echo_length(buf: bytes | bytearray, echo: bytes, silent: bool) -> int | None:
    """How many leading bytes of ``buf`` are the echo: ``len(echo)`` when it is all there, 0 when
    ``buf`` is not (or, after silence, no longer can be) the echo, None while a partial echo
    waits for the rest of it."""
    k = min(len(echo), len(buf))
    if buf[:k] != echo[:k]:
        return 0
    if k == len(echo):
        return k
    return 0 if silent else None
