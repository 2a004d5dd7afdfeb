"""Shared test helpers."""

from __future__ import annotations

import contextlib
import functools
import json
import os
import select
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager as ContextManager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from serving import stop

ROOT = Path(__file__).resolve().parents[1]

# Property tests draw the same examples on every run and machine (a failure seen once is seen again; no example
# database carried between runs): tests are deterministic.
with contextlib.suppress(ImportError):
    from hypothesis import settings as _hypothesis_settings

    _hypothesis_settings.register_profile("joints", derandomize=True, database=None)
    _hypothesis_settings.load_profile("joints")


# --- MKS firmware profiles ------------------------------------------------------------------------------------
# ``@pytest.mark.mks_firmware`` (on a test or a module): the test runs once per MKS firmware profile
# (joints.devices.quirks.MKS_FIRMWARES), ``@pytest.mark.mks_firmware("v1.0.6", "v1.0.9")`` on the ones named (a
# test of a later firmware's feature). While it runs, that profile is the MKS family's default, so every driver
# and twin built without a ``firmware`` (registry, config, direct construction) has it; the ``mks_firmware``
# fixture names it (None in unmarked tests) for what the default cannot reach (a config served by another process).
# ``mks_firmware(None)``: a test that names its firmware per case itself (runs once, as written).


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "mks_firmware(*profiles): run once per MKS firmware profile (default: all), "
                                       "that profile being the MKS default (fixture mks_firmware)")


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    marker = metafunc.definition.get_closest_marker("mks_firmware")
    if marker is not None and marker.args != (None,):
        from joints.devices.quirks import MKS_FIRMWARES

        unknown = set(marker.args) - set(MKS_FIRMWARES)
        assert not unknown, f"mks_firmware names no profile {sorted(unknown)}: {MKS_FIRMWARES}"
        metafunc.parametrize("mks_firmware", marker.args or MKS_FIRMWARES)


@pytest.fixture
def mks_firmware() -> str | None:
    """The MKS firmware profile of a test marked ``mks_firmware`` (None elsewhere)."""
    return None


@pytest.fixture(autouse=True)
def _mks_default_firmware(request: pytest.FixtureRequest, mks_firmware: str | None) -> None:
    if mks_firmware is not None:
        from types import MappingProxyType

        from joints.devices import quirks

        default = MappingProxyType({**quirks.DEFAULT_FIRMWARE, "mks": mks_firmware})
        request.getfixturevalue("monkeypatch").setattr(quirks, "DEFAULT_FIRMWARE", default)


# Headless rendering for every test module, whichever imports MuJoCo first (envs does the same on import).
if sys.platform.startswith("linux") and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")


@functools.cache
def _kernels_compiled() -> None:
    """Compile the twins' kernels once, here, into numba's disk cache (joints.sim.kernel.cache_dir).

    A served world loads them from there before it prints its port; on a cold cache (a fresh machine,
    another Python) it would compile them first, which on a loaded 2-core machine takes longer than the
    startup bound below allows, and the bound is for starting a server, not for the compiler.
    """
    from joints.sim import kernel

    if not kernel.default_mode():
        return
    import joints

    with joints.open(ROOT / "joints" / "configs" / "erob_pendulum.toml", backend="sim") as rig:
        rig.sleep(0.01)  # a world with compiled twins: every kernel compiled (joints.sim.stepping._warm)


@contextlib.contextmanager
def _serve(config: Path, *, bus: str = "rs485", startup: float = 30.0) -> Iterator[str]:
    """Run ``joints sim serve CONFIG`` in another process; yield the pty port of ``bus``.

    The server must print its port within ``startup`` seconds and exit with 0 on SIGTERM.
    """
    if sys.platform == "win32":
        pytest.skip("pseudo-terminals need POSIX")
    _kernels_compiled()
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
        stop(proc)


@pytest.fixture(scope="session")
def sim_server() -> Callable[..., ContextManager[str]]:
    """``with sim_server(config_path) as port:`` - a served emulated bus in another process."""
    return _serve


@dataclass
class Served:
    """A `joints sim serve` process: where each bus is, and a hardware config that points there."""

    proc: subprocess.Popen[str]
    lines: dict[str, dict[str, Any]]
    hardware: Path  #: the served config as a hardware config (`--hardware-config`)
    buffer: bytearray

    def port(self, bus: str) -> str:
        return str(self.lines[bus]["port"])

    def line(self, timeout: float) -> dict[str, Any]:
        """The next JSON line the server prints (read from the pipe itself: no hidden buffering)."""
        assert self.proc.stdout is not None
        fd = self.proc.stdout.fileno()
        end = time.monotonic() + timeout
        while b"\n" not in self.buffer:
            ready, _, _ = select.select([fd], [], [], max(0.0, end - time.monotonic()))
            assert ready, f"joints sim serve printed nothing within {timeout:.0f} s"
            chunk = os.read(fd, 65536)
            assert chunk, f"joints sim serve ended: {self.proc.stderr.read() if self.proc.stderr else ''}"
            self.buffer += chunk
        text, _, rest = bytes(self.buffer).partition(b"\n")
        self.buffer[:] = rest
        answer: dict[str, Any] = json.loads(text)
        return answer

    def command(self, text: str, timeout: float = 30.0) -> dict[str, Any]:
        """Send a control command (the server runs with --control) and return its JSON answer."""
        assert self.proc.stdin is not None
        self.proc.stdin.write(text + "\n")
        self.proc.stdin.flush()
        return self.line(timeout)


@contextlib.contextmanager
def _serve_all(config: Path, *args: str, startup: float = 30.0) -> Iterator[Served]:
    """Serve every bus of ``config`` (serial on ptys, CAN on udp_multicast) with ``--control``."""
    if sys.platform == "win32":
        pytest.skip("serving needs POSIX")
    _kernels_compiled()
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    n_buses = len(tomllib.loads(config.read_text(encoding="utf-8")).get("buses", {}))
    hardware = config.with_name(config.stem + ".served.toml")
    proc = subprocess.Popen([sys.executable, "-m", "joints", "sim", "serve", str(config), "--control",
                             "--hardware-config", str(hardware), *args],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        served = Served(proc, {}, hardware, bytearray())
        while len(served.lines) < n_buses:
            line = served.line(startup)
            served.lines[line["bus"]] = line
        yield served
    finally:
        stop(proc)


@pytest.fixture(scope="session")
def sim_served() -> Callable[..., ContextManager[Served]]:
    """``with sim_served(config_path) as served:`` - every bus of a config served in another process
    (``served.lines``, ``served.hardware``: a hardware config for the served buses, ``served.command``)."""
    return _serve_all
