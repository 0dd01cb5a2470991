"""Frames of a scene: the deformed sphere coloured by displacement, the target as a wireframe and
the applied force as an arrow; with the laryngoscope, its side view (blade, incisors, hand and the
tongue's midline section) beside it. matplotlib is imported only when the first frame is drawn."""

from __future__ import annotations

from typing import Any

import numpy as np

from .world import World

RENDER_MODES = ("rgb_array", "human")


def check_render_mode(render_mode: str | None) -> None:
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"render_mode={render_mode!r} is not one of {[None, *RENDER_MODES]}")


class SceneRenderer:
    """Draws one env's state; ``human`` shows a window, ``rgb_array`` returns ``(H, W, 3)`` uint8."""

    def __init__(self, world: World, render_mode: str) -> None:
        self.world = world
        self.render_mode = render_mode
        self._figure: Any = None
        self._panel: Any = None

    def frame(self, b: np.ndarray, target_b: np.ndarray, features: np.ndarray, caption: str = "",
              device: dict[str, Any] | None = None) -> np.ndarray | None:
        """Draw the shape ``b`` against ``target_b`` with the force of ``features``; with a ``device``
        drawing (the laryngoscope), its side view appears to the right of the sphere."""
        scene = self.world.scene
        if self._figure is None:
            from ..render import SagittalPanel, SphereFigure     # matplotlib only when something is drawn

            panels = 1 if device is None else 2
            self._figure = SphereFigure(scene.mesh.triangles, scene.tissue.radius, self.world.config["render"]["size"],
                                        interactive=self.render_mode == "human", panels=panels)
            if device is not None:
                self._panel = SagittalPanel(self._figure.figure, (0.5, 0.0, 0.5, 1.0), scene.mesh.triangles,
                                            scene.tissue.radius)
        n = scene.mesh.n_vertices
        points = scene.shape_model.decode(b).reshape(n, 3)
        target = scene.shape_model.decode(target_b).reshape(n, 3)
        contact, force = scene.layout.to_loads(np.asarray(features, dtype=np.float64)[None])
        scale = 0.3 * scene.tissue.radius / max(float(scene.workspace.high[2]), 1e-12)
        self._figure.update(points, scene.mesh.vertices, target, contact[0], force[0], scale, caption)
        if device is not None:
            self._panel.update(points, device)
        if self.render_mode == "human":
            self._figure.show()
            return None
        return self._figure.rgb()

    def close(self) -> None:
        if self._figure is not None:
            self._figure.close()
            self._figure = None
