"""Rendering of an env's MuJoCo scene: ``"rgb_array"`` (offscreen) and ``"human"`` (passive viewer).

The renderer only reads ``MjData`` (no physics side effects, so rendering never changes a
trajectory). In sim it shows the simulated world; on hardware the env fills a kinematic copy of
the model with the measured joint angles (a digital twin).

Headless machines need an offscreen GL backend: ``import envs`` sets ``MUJOCO_GL=egl`` when the
variable is unset, no display is available and MuJoCo is not imported yet. ``"human"`` without a
display warns once and shows nothing.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import logger


def _no_viewer_reason() -> str:
    """Why the interactive viewer cannot open here ('' if it can): it needs GLFW and a display.

    Checked up front because GLFW without a display can end the process instead of raising.
    """
    gl = os.environ.get("MUJOCO_GL", "glfw").lower()
    if gl not in ("glfw", ""):
        return f"MUJOCO_GL={gl} is an offscreen backend (the viewer needs glfw)"
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return "no display (DISPLAY / WAYLAND_DISPLAY unset)"
    return ""


@dataclass(frozen=True)
class CameraSpec:
    """A free camera looking at ``lookat`` [m] from ``distance`` [m], angles in degrees."""

    lookat: tuple[float, float, float] = (0.0, 0.0, 0.3)
    distance: float = 1.5
    azimuth: float = 135.0
    elevation: float = -30.0

    def apply(self, cam: Any) -> None:
        import mujoco

        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = self.lookat
        cam.distance = self.distance
        cam.azimuth = self.azimuth
        cam.elevation = self.elevation


class SceneRenderer:
    """Draws ``data`` of ``model`` for one render mode."""

    def __init__(self, mode: str, model: Any, data: Any, *, width: int, height: int, camera: CameraSpec) -> None:
        import mujoco

        self.mode = mode
        self.model = model
        self.data = data
        self.width = int(width)
        self.height = int(height)
        self.camera = camera
        self._mj = mujoco
        self._renderer: Any = None
        self._viewer: Any = None
        self._failed = False
        self._pace: tuple[float, float] | None = None  #: (wall, sim) at the first human frame
        self.markers: list[tuple[Any, Sequence[float]]] = []

    def _rgb(self) -> np.ndarray:
        if self._renderer is None:
            vis = self.model.vis.global_
            vis.offwidth = max(int(vis.offwidth), self.width)
            vis.offheight = max(int(vis.offheight), self.height)
            self._renderer = self._mj.Renderer(self.model, self.height, self.width)
            self._cam = self._mj.MjvCamera()
            self.camera.apply(self._cam)
        self._renderer.update_scene(self.data, camera=self._cam)
        self._add_markers(self._renderer.scene)
        return np.asarray(self._renderer.render())

    def _add_markers(self, scene: Any) -> None:
        """Draw the task's markers (e.g. the target) as translucent spheres."""
        for pos, rgba in self.markers:
            if scene.ngeom >= scene.maxgeom:
                return
            self._mj.mjv_initGeom(scene.geoms[scene.ngeom], self._mj.mjtGeom.mjGEOM_SPHERE,
                                  np.array([0.02, 0.0, 0.0]), np.asarray(pos, dtype=np.float64),
                                  np.eye(3).reshape(-1), np.asarray(rgba, dtype=np.float32))
            scene.ngeom += 1

    def _human(self, sim_time: float) -> None:
        if self._failed:
            return
        if self._viewer is None:
            why = _no_viewer_reason()
            if why:
                self._failed = True
                logger.warn(f"render_mode='human' shows nothing: {why}")
                return
            try:
                from mujoco import viewer

                self._viewer = viewer.launch_passive(self.model, self.data, show_left_ui=False, show_right_ui=False)
                self.camera.apply(self._viewer.cam)
            except Exception as exc:  # noqa: BLE001 - no display, no GL: nothing to show
                self._failed = True
                logger.warn(f"render_mode='human' shows nothing: the MuJoCo viewer could not start ({exc})")
                return
        if not self._viewer.is_running():
            return
        with self._viewer.lock():
            self._viewer.user_scn.ngeom = 0
            self._add_markers(self._viewer.user_scn)
        self._viewer.sync()
        # a human watches in real time: hold the frame until the wall clock catches up
        now = time.monotonic()
        if self._pace is None:
            self._pace = (now, sim_time)
        ahead = (sim_time - self._pace[1]) - (now - self._pace[0])
        if 0 < ahead < 1.0:
            time.sleep(ahead)
        elif ahead >= 1.0 or ahead < -1.0:
            self._pace = (now, sim_time)

    def render(self, sim_time: float = 0.0, markers: Sequence[tuple[Any, Sequence[float]]] = ()) -> np.ndarray | None:
        """A frame (``rgb_array``: uint8 array (height, width, 3)) with ``markers`` = [(position [m], rgba)]."""
        self.markers = list(markers)
        if self.mode == "rgb_array":
            return self._rgb()
        self._human(sim_time)
        return None

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self._viewer is not None:
            try:
                self._viewer.close()
            finally:
                self._viewer = None
