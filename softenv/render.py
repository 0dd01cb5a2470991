"""Headless drawing of deformed spheres with matplotlib (imported only by code that renders).

Surfaces are projected orthographically and painted back to front as a 2-D ``PolyCollection``
(back faces culled, Lambert shading), which is several times faster than ``mplot3d`` and needs no
display. :class:`SphereFigure` keeps one figure and updates it in place, for environment frames;
:func:`draw_surface` draws once, for report figures.
"""

from __future__ import annotations

from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.cm import ScalarMappable
from matplotlib.colors import LinearSegmentedColormap, Normalize
from matplotlib.figure import Figure

from .projection import View, capsule, midline_profile, shaded_faces, visible_edges

# pale pink at rest, deep red where the tissue is displaced most
TONGUE = LinearSegmentedColormap.from_list("softenv_tongue", ["#f6d3cf", "#e8909a", "#c0394e", "#6e0f26"])
TOP_OF_SCALE = 0.4        # an env frame's colour scale ends at this fraction of the radius of displacement


def displacement_colorbar(fig: Any, axes: Any, radius: float, top: float | None = None, **options: Any) -> Any:
    """The colour bar of displacement in mm beside ``axes``: 0 to ``top`` metres (by default the top of an
    env frame's scale, ``TOP_OF_SCALE`` of the ``radius``)."""
    top = TOP_OF_SCALE * radius if top is None else top
    mappable = ScalarMappable(norm=Normalize(0.0, top * 1e3), cmap=TONGUE)
    return fig.colorbar(mappable, ax=axes, **{"label": "tongue displacement (mm)", **options})


def draw_surface(ax: Any, points: np.ndarray, triangles: np.ndarray, values: np.ndarray, *, view: View | None = None,
                 cmap: Any = TONGUE, vmin: float | None = None, vmax: float | None = None, limit: float | None = None,
                 wireframe: np.ndarray | None = None, title: str | None = None) -> PolyCollection:
    """Draw a surface (coloured by per-vertex ``values``) and optionally a wireframe of ``wireframe`` points."""
    view = view or View()
    vmin = float(values.min()) if vmin is None else vmin
    vmax = float(values.max()) if vmax is None else vmax
    cmap = matplotlib.colormaps[cmap] if isinstance(cmap, str) else cmap
    polys, colors = shaded_faces(points, triangles, values, view, cmap, vmin, vmax)
    coll = PolyCollection(polys, facecolors=colors, edgecolors="none", antialiaseds=False)
    ax.add_collection(coll)
    if wireframe is not None:
        ax.add_collection(LineCollection(visible_edges(wireframe, triangles, view), colors="k", linewidths=0.3, alpha=0.5))
    lim = limit if limit is not None else 1.15 * float(np.abs(points).max())
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.axis("off")
    if title:
        ax.set_title(title, fontsize=9)
    return coll


class SphereFigure:
    """A reusable figure for environment frames: update the surface, target wireframe and force arrow.

    Args:
        triangles: the mesh's triangles.
        radius: sphere radius (sets the view limits).
        size_px: frame width and height in pixels.
        max_displacement: displacement (m) at the top of the colour scale.
    """

    def __init__(self, triangles: np.ndarray, radius: float, size_px: int = 320, max_displacement: float | None = None,
                 view: View | None = None, interactive: bool = False, panels: int = 1) -> None:
        self.triangles = triangles
        self.radius = radius
        self.view = view or View()
        self.vmax = max_displacement if max_displacement is not None else TOP_OF_SCALE * radius
        self.cmap = TONGUE
        dpi = 100
        size = (panels * size_px / dpi, size_px / dpi)          # further panels sit right of the sphere
        if interactive:
            self.figure = plt.figure(figsize=size, dpi=dpi)
        else:
            self.figure = Figure(figsize=size, dpi=dpi)
            FigureCanvasAgg(self.figure)
        self.ax = self.figure.add_axes((0, 0, 1 / panels, 1))
        lim = 1.25 * radius
        self.ax.set_xlim(-lim, lim)
        self.ax.set_ylim(-lim, lim)
        self.ax.set_aspect("equal")
        self.ax.axis("off")
        self.surface = PolyCollection([], edgecolors="none", antialiaseds=False)
        self.target = LineCollection([], colors="#2a9df4", linewidths=0.4, alpha=0.8)
        self.arrow = self.ax.annotate("", xy=(0, 0), xytext=(0, 0),
                                      arrowprops={"arrowstyle": "-|>", "color": "#19c37d", "lw": 2.0})
        self.text = self.ax.text(0.02, 0.97, "", transform=self.ax.transAxes, va="top", fontsize=8, color="0.15")
        self.ax.add_collection(self.surface)
        self.ax.add_collection(self.target)

    def update(self, points: np.ndarray, rest: np.ndarray, target: np.ndarray | None = None,
               contact: np.ndarray | None = None, force: np.ndarray | None = None, force_scale: float = 1.0,
               caption: str = "") -> None:
        """Redraw with current ``points`` (coloured by displacement from ``rest``), target and force (N)."""
        disp = np.linalg.norm(points - rest, axis=1)
        polys, colors = shaded_faces(points, self.triangles, disp, self.view, self.cmap, 0.0, self.vmax)
        self.surface.set_verts(polys)
        self.surface.set_facecolors(colors)
        self.target.set_segments([] if target is None else visible_edges(target, self.triangles, self.view))
        if contact is not None and force is not None and np.linalg.norm(force) > 0:
            tip = self.view.project(contact[None])[0, :2]
            tail = self.view.project((contact - force * force_scale)[None])[0, :2]
            self.arrow.set_position(tuple(tail))
            self.arrow.xy = tuple(tip)
            self.arrow.set_visible(True)
        else:
            self.arrow.set_visible(False)
        self.text.set_text(caption)

    def rgb(self) -> np.ndarray:
        """The current frame as an ``(H, W, 3)`` uint8 array."""
        canvas = self.figure.canvas
        canvas.draw()
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()

    def show(self) -> None:
        """Display the frame in a window (``human`` mode); a no-op without a display."""
        self.figure.canvas.draw_idle()
        plt.pause(0.001)

    def close(self) -> None:
        if plt.fignum_exists(getattr(self.figure, "number", -1)):
            plt.close(self.figure)


class SagittalPanel:
    """The device's side view beside the sphere: the tongue's midline section (deformed and at
    rest), the blade, the incisors, the hand and the contact force."""

    def __init__(self, figure: Any, rect: tuple[float, float, float, float], triangles: np.ndarray,
                 radius: float) -> None:
        self.triangles = triangles
        self.ax = figure.add_axes(rect)
        self.ax.set_xlim(-2.4 * radius, 2.8 * radius)          # the blade reaches 2 R behind, the hand 2.3 R ahead
        self.ax.set_ylim(-1.3 * radius, 3.9 * radius)
        self.ax.set_aspect("equal")
        self.ax.axis("off")
        theta = np.linspace(0, 2 * np.pi, 97)
        self.ax.plot(radius * np.cos(theta), radius * np.sin(theta), ls="--", lw=0.6, color="0.6")
        self.tongue = self.ax.fill([0], [0], color="#e8909a", alpha=0.9, lw=0.8, ec="#6e0f26")[0]
        self.blade = self.ax.fill([0], [0], color="#9aa5b1", ec="#2f3b48", lw=1.0)[0]
        self.incisor = self.ax.fill([0], [0], color="#fffbe6", ec="#8a7f50", lw=1.0)[0]
        self.lower_incisor = self.ax.fill([0], [0], color="#fffbe6", ec="#8a7f50", lw=1.0, visible=False)[0]
        (self.handle,) = self.ax.plot([], [], color="#2f3b48", lw=4.0, solid_capstyle="round")
        (self.hand,) = self.ax.plot([], [], "o", color="#19c37d", ms=6)
        self.arrow = self.ax.annotate("", xy=(0, 0), xytext=(0, 0),
                                      arrowprops={"arrowstyle": "-|>", "color": "#19c37d", "lw": 1.5})
        self.text = self.ax.text(0.02, 0.02, "", transform=self.ax.transAxes, fontsize=7, color="0.15")
        self.radius = radius

    def update(self, points: np.ndarray, device: dict[str, Any]) -> None:
        """Redraw with the deformed surface ``points`` ``(n, 3)`` and a device drawing (see
        ``softenv.devices.laryngoscope``)."""
        profile = midline_profile(points, self.triangles)
        self.tongue.set_xy(profile)
        self.blade.set_xy(device["outline"])
        a, b, r = device["incisor"]
        self.incisor.set_xy(capsule(np.asarray(a), np.asarray(b), r))
        if device["lower_incisor"] is not None:
            a, b, r = device["lower_incisor"]
            self.lower_incisor.set_xy(capsule(np.asarray(a), np.asarray(b), r))
            self.lower_incisor.set_visible(True)
        gx, gy, _ = device["hand"]
        heel, top = device["handle"]
        self.handle.set_data([heel[0], top[0]], [heel[1], top[1]])
        self.hand.set_data([gx], [gy])
        contact = device["contact"]
        if contact is not None and device["tongue_force"] > 0:
            c = np.asarray(contact)
            tip = c * (1 - 1e-3)
            tail = c + c / np.linalg.norm(c) * 0.02 * device["tongue_force"] / 40.0 * self.radius / 0.03
            self.arrow.set_position(tuple(tail))
            self.arrow.xy = tuple(tip)
            self.arrow.set_visible(True)
        else:
            self.arrow.set_visible(False)
        self.text.set_text(f"tongue {device['tongue_force']:.1f} N   incisors {device['incisor_force']:.1f} N")
