"""Fixtures of the sim tests."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from simkit import canopen_arm


@pytest.fixture
def arm() -> Iterator[Any]:
    """The arm on CANopen at 20 ms (:func:`simkit.canopen_arm`), closed after the test."""
    pytest.importorskip("mujoco")
    pytest.importorskip("gymnasium")
    env = canopen_arm()
    try:
        yield env
    finally:
        env.close()
