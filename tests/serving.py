"""Ending a `joints sim serve` process the tests started."""

from __future__ import annotations

import subprocess


def stop(proc: subprocess.Popen[str], timeout: float = 30.0) -> None:
    """SIGTERM ``proc``; it must exit with 0 within ``timeout`` s (killed and the wait's error raised otherwise: the
    bound is for a server that does not stop, generous for a loaded machine)."""
    proc.terminate()
    try:
        rc = proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    assert rc == 0, proc.stderr.read() if proc.stderr else rc
