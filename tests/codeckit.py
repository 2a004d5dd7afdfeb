"""Helpers of the codec tests: hex text to bytes, and draining a stream codec."""

from __future__ import annotations

from typing import Any

from joints.errors import FrameError


def h(text: str) -> bytes:
    return bytes.fromhex(text)


def drain(codec: Any) -> tuple[list[Any], list[FrameError]]:
    """Every message and every frame error the codec can produce from its buffer now."""
    msgs: list[Any] = []
    errors: list[FrameError] = []
    for _ in range(10_000):
        try:
            msg = codec.next_message()
        except FrameError as exc:
            errors.append(exc)
            continue
        if msg is None:
            return msgs, errors
        msgs.append(msg)
    raise AssertionError("codec does not make progress")
