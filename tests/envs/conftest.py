"""Gymnasium env tests: need gymnasium and mujoco; rendering uses EGL on Linux unless MUJOCO_GL says otherwise."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager as ContextManager
from pathlib import Path

import pytest

# Offscreen rendering in tests, also on a desktop (no viewer windows pop up; "human" then warns).
if sys.platform.startswith("linux") and "MUJOCO_GL" not in os.environ and "mujoco" not in sys.modules:
    os.environ["MUJOCO_GL"] = "egl"

pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")


_GL: list[str] = []


@pytest.fixture(scope="session")
def gl_unavailable() -> str:
    """'' when MuJoCo can render offscreen here, else the reason (checked once)."""
    if not _GL:
        try:
            import mujoco

            model = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='1'/></worldbody></mujoco>")
            renderer = mujoco.Renderer(model, 16, 16)
            renderer.update_scene(mujoco.MjData(model))
            renderer.render()
            renderer.close()
            _GL.append("")
        except Exception as exc:  # noqa: BLE001 - any GL failure means: no offscreen rendering here
            _GL.append(f"no offscreen GL backend (MUJOCO_GL={os.environ.get('MUJOCO_GL', 'unset')}): {exc}")
    return _GL[0]


@pytest.fixture
def serve_shipped(tmp_path: Path, sim_server: Callable[..., ContextManager[str]]) -> Callable[[str], ContextManager[str]]:
    """``with serve_shipped("erob_reach") as port:`` - ``joints sim serve`` of a shipped env config in
    another process (its pty port); skipped where pseudo-terminals or pyserial are missing."""
    pytest.importorskip("serial")
    if sys.platform == "win32":
        pytest.skip("pseudo-terminals need POSIX")
    import envs

    @contextlib.contextmanager
    def serve(name: str) -> Iterator[str]:
        cfg = tmp_path / "served.toml"
        with envs.config_path(name) as p:
            cfg.write_text(p.read_text())
        with sim_server(cfg) as port:
            yield port

    return serve
