"""Fixtures of the command-line tests (the world itself: clikit.py)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager as ContextManager
from pathlib import Path
from typing import Any

import pytest
from clikit import write_world


@pytest.fixture(scope="module")
def world_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("cli")


@pytest.fixture(scope="module")
def sim_config(world_dir: Path) -> Path:
    """The world as an in-process sim config."""
    pytest.importorskip("mujoco")
    return write_world(world_dir)


@pytest.fixture(scope="module")
def served(sim_config: Path, sim_served: Callable[..., ContextManager[Any]]) -> Iterator[Any]:
    """The world served in another process (every bus); ``served.hardware`` is the config to reach it."""
    pytest.importorskip("serial")
    pytest.importorskip("msgpack")  # udp_multicast
    with sim_served(sim_config) as s:
        yield s
