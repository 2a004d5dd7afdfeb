"""Shared test helpers."""

from __future__ import annotations

import contextlib
import json
import os
import select
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import ContextManager

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Headless rendering for every test module, whichever imports MuJoCo first (envs does the same on import).
if sys.platform.startswith("linux") and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")


@contextlib.contextmanager
def _serve(config: Path, *, bus: str = "rs485", startup: float = 30.0) -> Iterator[str]:
    """Run ``joints sim serve CONFIG`` in another process; yield the pty port of ``bus``.

    The server must print its port within ``startup`` seconds and exit with 0 on SIGTERM.
    """
    if sys.platform == "win32":
        pytest.skip("pseudo-terminals need POSIX")
    proc = subprocess.Popen([sys.executable, "-m", "joints", "sim", "serve", str(config)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], startup)
        assert ready, f"joints sim serve printed no port within {startup:.0f} s"
        assert proc.stdout is not None
        ports = {}
        line = json.loads(proc.stdout.readline())
        ports[line["bus"]] = line["port"]
        assert bus in ports and ports[bus].startswith("/dev/"), ports
        yield ports[bus]
    finally:
        proc.terminate()
        try:
            rc = proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
        assert rc == 0, proc.stderr.read() if proc.stderr else rc


@pytest.fixture(scope="session")
def sim_server() -> Callable[..., ContextManager[str]]:
    """``with sim_server(config_path) as port:`` - a served emulated bus in another process."""
    return _serve
