"""Headless drawing of deformed spheres with matplotlib (imported only by code that renders).

Surfaces are projected orthographically and painted back to front as a 2-D ``PolyCollection``
(back faces culled, Lambert shading), which is several times faster than ``mplot3d`` and needs no
display. :class:`SphereFigure` keeps one figure and updates it in place, for environment frames;
:func:`draw_surface` draws once, for report figures.
"""

from __future__ import annotations

import math
from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.cm import ScalarMappable
from matplotlib.colors import LinearSegmentedColormap, Normalize
from matplotlib.figure import Figure

# pale pink at rest, deep red where the tissue is displaced most
TONGUE = LinearSegmentedColormap.from_list("softenv_tongue", ["#f6d3cf", "#e8909a", "#c0394e", "#6e0f26"])
TOP_OF_SCALE = 0.4        # an env frame's colour scale ends at this fraction of the radius of displacement


def displacement_colorbar(fig: Any, axes: Any, radius: float, top: float | None = None, **options: Any) -> Any:
    """The colour bar of displacement in mm beside ``axes``: 0 to ``top`` metres (by default the top of an
    env frame's scale, ``TOP_OF_SCALE`` of the ``radius``)."""
    top = TOP_OF_SCALE * radius if top is None else top
    mappable = ScalarMappable(norm=Normalize(0.0, top * 1e3), cmap=TONGUE)
    return fig.colorbar(mappable, ax=axes, **{"label": "tongue displacement (mm)", **options})


class View:
    """Orthographic camera: ``elevation`` above the x-y plane and ``azimuth`` around z, in degrees."""

    def __init__(self, elevation: float = 30.0, azimuth: float = -50.0) -> None:
        el, az = math.radians(elevation), math.radians(azimuth)
        forward = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])  # toward viewer
        right = np.array([-math.sin(az), math.cos(az), 0.0])
        up = np.cross(forward, right)
        self.basis = np.stack([right, up, forward])  # rows: screen x, screen y, depth (toward viewer)
        self.light = forward * 0.6 + up * 0.6 + right * 0.3
        self.light /= np.linalg.norm(self.light)

    def project(self, points: np.ndarray) -> np.ndarray:
        """``(n, 3)`` world points -> ``(n, 3)`` screen x, screen y, depth."""
        return points @ self.basis.T


def shaded_faces(points: np.ndarray, triangles: np.ndarray, values: np.ndarray, view: View, cmap: Any,
                 vmin: float, vmax: float) -> tuple[np.ndarray, np.ndarray]:
    """Front-facing triangles in 2-D, back to front, and their shaded RGBA colours."""
    screen = view.project(points)
    tri = screen[triangles]                                   # (t, 3, 3)
    world = points[triangles]
    normal = np.cross(world[:, 1] - world[:, 0], world[:, 2] - world[:, 0])
    facing = normal @ view.basis[2] > 0
    order = np.argsort(tri[facing, :, 2].mean(axis=1))
    keep = np.flatnonzero(facing)[order]
    unit = normal[keep] / np.maximum(np.linalg.norm(normal[keep], axis=1, keepdims=True), 1e-300)
    lambert = 0.6 + 0.4 * np.clip(unit @ view.light, 0.0, 1.0)
    face_value = values[triangles[keep]].mean(axis=1)
    span = vmax - vmin if vmax > vmin else 1.0
    rgba = cmap(np.clip((face_value - vmin) / span, 0.0, 1.0))
    rgba[:, :3] *= lambert[:, None]
    return tri[keep, :, :2], rgba


def visible_edges(points: np.ndarray, triangles: np.ndarray, view: View) -> np.ndarray:
    """2-D segments of the front-facing triangles' edges (a wireframe), ``(m, 2, 2)``."""
    world = points[triangles]
    normal = np.cross(world[:, 1] - world[:, 0], world[:, 2] - world[:, 0])
    front = triangles[normal @ view.basis[2] > 0]
    edges = np.unique(np.sort(np.concatenate([front[:, [0, 1]], front[:, [1, 2]], front[:, [2, 0]]]), axis=1), axis=0)
    screen = view.project(points)[:, :2]
    return screen[edges]


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


def capsule(a: np.ndarray, b: np.ndarray, radius: float, n: int = 12) -> np.ndarray:
    """Outline ``(2 n + 2, 2)`` of a rounded bar from ``a`` to ``b``."""
    angle = math.atan2(b[1] - a[1], b[0] - a[0])
    ends = [(b, np.linspace(angle - math.pi / 2, angle + math.pi / 2, n + 1)),
            (a, np.linspace(angle + math.pi / 2, angle + 3 * math.pi / 2, n + 1))]
    return np.concatenate([c + radius * np.stack([np.cos(t), np.sin(t)], axis=1) for c, t in ends])


def midline_profile(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The surface's section by the sagittal plane ``y = 0``: ``(m, 2)`` points ``(x, z)`` ordered by
    angle (edges that cross the plane, cut by linear interpolation)."""
    edges = np.unique(np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]),
                              axis=1), axis=0)
    a, b = points[edges[:, 0]], points[edges[:, 1]]
    cross = (a[:, 1] * b[:, 1] < 0) | ((a[:, 1] == 0) & (b[:, 1] != 0))
    t = a[cross, 1] / (a[cross, 1] - b[cross, 1])
    cut = a[cross] + t[:, None] * (b[cross] - a[cross])
    order = np.argsort(np.arctan2(cut[:, 2], cut[:, 0]))
    return cut[order][:, [0, 2]]


class SagittalPanel:
    """The device's side view beside the sphere: the tongue's midline section (deformed and at
    rest), the blade, the upper incisors, the hand and the contact force."""

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
