"""What ``softenv play`` draws, in pygame: the start screen, each frame of a session, the end screen.

A frame (1280 x 720 px) has four parts:

* **the side view**, to scale, of the midline section: the tongue as it is and the target's outline
  (dashed green), the blade and handle drawn as a laryngoscope (the light at the blade's tip), the
  hand, the upper incisors (red, with the force, while the blade touches them), and the line of sight
  from the laryngoscopist's eye to the glottis, green where it is clear (the glottic view,
  :func:`softenv.devices.laryngoscope.clinical.glottic_view`). It is sized to the hand's whole workspace at every wrist
  angle, so nothing leaves it, with a scale bar in its corner; a label whose place would cover a drawing
  moves to the nearest blank place around what it names;
* **the tongue in 3D**, seen from the mouth, coloured by how far each point still is from the target,
  the target as a green wireframe: the press and the sideways sweep both show here;
* **gauges** with scales in newtons: the tongue force (the safe limit labelled, the bar red past it),
  the force on the incisors (the score's limit labelled) and the force rendered to the hand;
* **status and controls**: the shape error against the target's tolerance, the glottic view, the
  time, and every control (:data:`softenv.training.inputs.CONTROLS`).

Every labelled thing drawn is recorded in :attr:`PlayView.drawn` (name -> screen rectangle), so tests
check what is on screen, not only that a frame was made.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..airway import scene_title
from ..devices.laryngoscope import clinical
from ..projection import View, capsule, shaded_faces, visible_edges
from .inputs import CONTROLS

Rect = tuple[int, int, int, int]
SIZE = (1280, 720)
SIDE: Rect = (10, 44, 620, 556)
SOLID: Rect = (640, 44, 300, 300)
GAUGES: Rect = (950, 44, 320, 300)
STATUS: Rect = (640, 354, 630, 246)
HELP: Rect = (10, 608, 1260, 104)
INK = (25, 25, 30)
PAPER = (250, 248, 244)
PANEL = (255, 255, 255)
TONGUE = (232, 144, 154)
TONGUE_EDGE = (110, 15, 38)
TARGET = (20, 140, 60)
STEEL = (155, 165, 177)
STEEL_EDGE = (47, 59, 72)
TOOTH = (255, 251, 230)
DANGER = (205, 40, 40)
CLEAR = (160, 225, 160)
BLOCKED = (215, 215, 215)
HAND = (40, 90, 200)
SCALE_BAR_MM = (5, 10, 20, 50, 100)          # the side view's scale bar: the first of these at least 60 px long
# the 3D tongue's colour ramp: on target (green) -> halfway (amber) -> as far as at rest or more (red)
RAMP = np.array([[120, 200, 120], [240, 200, 80], [210, 60, 60]], dtype=np.float64) / 255.0


def ramp(x: np.ndarray) -> np.ndarray:
    """RGBA ``(n, 4)`` in [0, 1] of values ``x`` in [0, 1] on :data:`RAMP` (a colour map for shaded_faces)."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0) * (len(RAMP) - 1)
    i = np.minimum(x.astype(int), len(RAMP) - 2)
    f = (x - i)[:, None]
    return np.column_stack([RAMP[i] * (1.0 - f) + RAMP[i + 1] * f, np.ones(len(x))])


class PlayView:
    """Draws a session of ``env`` (SoftSphereHaptic-v0, or an airway grade: its title names it) on ``screen``; ``incisor_limit_N``: the score's
    limit on the force on the incisors."""

    def __init__(self, pygame: Any, screen: Any, env: Any, incisor_limit_N: float) -> None:
        self.pg, self.screen = pygame, screen
        self.fonts: dict[int, Any] = {}
        world = env.world
        self.radius = world.config["tissue"]["radius"]
        self.triangles = world.scene.mesh.triangles
        self.target = world.vertices(env.target_b[0]).reshape(-1, 3)              # in radii
        rest = world.vertices(world.b_rest).reshape(-1, 3)
        self.error_top_mm = max(float(np.linalg.norm(self.target - rest, axis=1).max()) * self.radius * 1e3, 1e-9)
        self.target_profile = _by_angle(clinical.sagittal_profile(self.target, self.triangles) * self.radius)
        self.safe_N = world.weights["safe_force"]
        self.max_force_N = world.config["device"]["max_normal_force"]
        self.incisor_limit_N = incisor_limit_N
        self.success_mm = env.success_error_mm
        self.view3d = View(elevation=30.0, azimuth=-20.0)
        self._fit_side_view(env)
        colours = (ramp(np.linspace(0.0, 1.0, SOLID[2] - 40)) * 255).astype(np.uint8)[:, :3]
        self._colour_bar = pygame.surfarray.make_surface(np.repeat(colours[:, None, :], 10, axis=1))
        self._mesh = pygame.Surface(SOLID[2:], pygame.SRCALPHA)       # made once: drawn on every frame
        self._shade = pygame.Surface(SIZE, pygame.SRCALPHA)
        self._shade.fill((30, 30, 40, 110))
        self.drawn: dict[str, Rect] = {}
        self.last_forces: dict[str, float] = {}             # what the gauges showed last (N)
        self._labels: list[tuple[str, Any, tuple[int, int], tuple[int, int, int], str | None, bool]] = []

    # -- screens ---------------------------------------------------------------------------------------
    def start_screen(self, env: Any) -> None:
        """The scene at rest under a card stating the task and the controls."""
        self.frame(env, {}, 0, 1, 0.0)
        card = self._card((240, 150, 800, 400))
        x, y = card[0] + 30, card[1] + 24
        self._text("Laryngoscopy: move the tongue to the target", (x, y), 34, name="title")
        y += 46
        task = ("Insert the blade over the tongue, lift along the handle to press the tongue down and sweep it "
                "aside until it fits the dashed green outline, gently and without levering on the upper teeth.")
        y = self._wrapped(task, (x, y), card[2] - 60, 26, name="task") + 14
        for key, what in CONTROLS:
            self._text(key, (x, y), 22)
            self._text(what, (x + 170, y), 22)
            y += 24
        self._text("Space, Enter or a click: start", (x, y + 10), 26, colour=TARGET, name="start")

    def end_screen(self, env: Any, info: dict[str, Any], steps_done: int, steps: int, dt: float,
                   report: dict[str, Any], advice: list[str], written: str) -> None:
        """The last frame under a card with the score, each part against the expert's and what to do better."""
        self.frame(env, info, steps_done, steps, dt)
        card = self._card((240, 90, 800, 520))
        x, y = card[0] + 30, card[1] + 20
        self._text(f"Score {report['score']:.1f} / 100", (x, y), 56, name="score")
        y += 56
        self._text("part", (x, y), 22)
        self._text("you", (x + 200, y), 22)
        self._text("expert", (x + 290, y), 22)
        self._text("weight", (x + 390, y), 22)
        y += 24
        for part, weight in report["weights"].items():
            mine, theirs = report[part], report["expert_parts"][part]
            colour = DANGER if mine < theirs - 0.05 else INK
            self._text(part, (x, y), 24)
            self._text(f"{100 * mine:.0f} %", (x + 200, y), 24, colour=colour, name=f"part:{part}")
            self._text(f"{100 * theirs:.0f} %", (x + 290, y), 24)
            self._text(f"{weight:g}", (x + 390, y), 24)
            y += 26
        y += 8
        self._text("To improve first:" if advice else "Every part is as good as the expert's.", (x, y), 26)
        y += 28
        for i, line in enumerate(advice):
            y = self._wrapped(f"{i + 1}. {line}", (x, y), card[2] - 60, 24, name=f"advice:{i}") + 4
        self._wrapped(f"Report: {written}", (x, card[1] + card[3] - 64), card[2] - 60, 20)
        self._text("Esc, Enter or close the window to leave", (x, card[1] + card[3] - 30), 24, colour=TARGET,
                   name="leave")

    def paused(self) -> None:
        """A band over the frame: paused, and how to go on."""
        card = self._card((440, 300, 400, 90))
        self._text("Paused: Space or P to go on", (card[0] + 30, card[1] + 32), 30, name="paused")

    def message(self, text: str) -> None:
        """A one-line card over the frame (e.g. while the session is scored)."""
        card = self._card((390, 310, 500, 70))
        self._text(text, (card[0] + 24, card[1] + 24), 28, name="message")

    # -- one frame -------------------------------------------------------------------------------------
    def frame(self, env: Any, info: dict[str, Any], step: int, steps: int, dt: float) -> None:
        """The whole window for ``env``'s state after ``step`` of ``steps`` control periods (``info``: that
        step's, empty before the first)."""
        self.drawn = {}
        self.screen.fill(PAPER)
        self._text(f"softenv play: {scene_title(env.world.config['airway'])}", (12, 12), 26)
        vertices = env.world.vertices(env.b).reshape(-1, 3)
        device = env.device.drawing()
        view_pct = self._side_view(vertices, device)
        self._solid(vertices)
        self._gauges(info, device)
        self._status(info, view_pct, step, steps, dt)
        self._help()

    def _side_view(self, vertices: np.ndarray, device: dict[str, Any]) -> float:
        pg, R = self.pg, self.radius
        self._panel(SIDE, "Side view (midline, to scale)")
        self.screen.set_clip(SIDE)
        profile = _by_angle(clinical.sagittal_profile(vertices, self.triangles) * R)
        view_pct = clinical.glottic_view(profile, R)
        eye = np.array(clinical.EYE) * R
        low, high = np.array(clinical.GLOTTIS_Z) * R
        gx = clinical.GLOTTIS_X * R
        shadow = high - view_pct / 100.0 * (high - low)
        pg.draw.polygon(self.screen, BLOCKED, [self.px(eye), self.px((gx, low)), self.px((gx, shadow))])
        if view_pct > 0:
            pg.draw.polygon(self.screen, CLEAR, [self.px(eye), self.px((gx, shadow)), self.px((gx, high))])
            self.drawn["line of sight"] = self._bbox([eye, (gx, shadow), (gx, high)])
        pg.draw.polygon(self.screen, TONGUE, self.pxs(profile))
        pg.draw.polygon(self.screen, TONGUE_EDGE, self.pxs(profile), 2)
        self.drawn["tongue"] = self._bbox(profile)
        self._dashed(self.target_profile, TARGET, 3)
        self.drawn["target outline"] = self._bbox(self.target_profile)
        pg.draw.line(self.screen, (120, 60, 160), self.px((gx, low)), self.px((gx, high)), 6)
        self._label("glottis", (gx, high), (-20, -22))
        pg.draw.circle(self.screen, INK, self.px(eye), 6, 2)
        self._label("eye", eye, (10, -8))
        self._label(f"line of sight: {view_pct:.0f} % of the glottis", eye, (-150, 12), name="glottic view")
        self._label("tongue", (0.0, -0.55 * R), (-24, 0), on_shape=True)
        # the laryngoscope: handle (knurled), blade, the light at the tip
        heel, top = device["handle"]
        grip = capsule(np.asarray(heel), np.asarray(top), 0.008)
        pg.draw.polygon(self.screen, (70, 78, 90), self.pxs(grip))
        self.drawn["handle"] = self._bbox(grip)
        along = (np.asarray(top) - heel) / max(float(np.linalg.norm(np.asarray(top) - heel)), 1e-12)
        across = np.array([-along[1], along[0]]) * 0.008
        for s in np.linspace(0.3, 0.9, 7):
            c = heel + s * (np.asarray(top) - heel)
            pg.draw.line(self.screen, (120, 128, 140), self.px(c - across), self.px(c + across), 1)
        outline = np.asarray(device["outline"])
        pg.draw.polygon(self.screen, STEEL, self.pxs(outline))
        pg.draw.polygon(self.screen, STEEL_EDGE, self.pxs(outline), 2)
        pg.draw.circle(self.screen, (255, 220, 70), self.px(outline[4] + 0.2 * (outline[3] - outline[4])), 5)
        self.drawn["blade"] = self._bbox(outline)
        self._label("blade", outline[3], (0, -22))
        self._label("handle", top, (12, -6))
        if device["lower_incisor"] is not None:            # the lower incisors: where the blade rests
            a, b, r = device["lower_incisor"]
            tooth = capsule(np.asarray(a), np.asarray(b), r)
            pg.draw.polygon(self.screen, TOOTH, self.pxs(tooth))
            pg.draw.polygon(self.screen, (138, 127, 80), self.pxs(tooth), 2)
            self.drawn["lower incisors"] = self._bbox(tooth)
        # the upper incisors: red with the force while touched
        a, b, r = device["incisor"]
        touched = device["incisor_force"] > 0.0
        tooth = capsule(np.asarray(a), np.asarray(b), r)
        pg.draw.polygon(self.screen, DANGER if touched else TOOTH, self.pxs(tooth))
        pg.draw.polygon(self.screen, (138, 127, 80), self.pxs(tooth), 2)
        self.drawn["upper incisors"] = self._bbox(tooth)
        if touched:
            pg.draw.circle(self.screen, DANGER, self.px(a), max(10, int(2.5 * r * self.scale)), 3)
            self._label(f"on the teeth! {device['incisor_force']:.1f} N", b, (12, -10), colour=DANGER,
                        name="incisor contact")
        else:
            self._label("upper incisors", b, (12, -10))
        # the hand, its wrist angle, and the tongue force at the contact
        hx, hz, pitch = device["hand"]
        centre = self.px((hx, hz))
        pg.draw.circle(self.screen, HAND, centre, 11, 3)
        tip = (hx + 0.015 * math.sin(pitch), hz + 0.015 * math.cos(pitch))
        pg.draw.line(self.screen, HAND, centre, self.px(tip), 3)
        self.drawn["hand"] = (centre[0] - 11, centre[1] - 11, 22, 22)
        self._label("hand", (hx, hz), (14, 4), colour=HAND)
        if device["contact"] is not None and device["tongue_force"] > 0:
            c = np.asarray(device["contact"])
            pg.draw.circle(self.screen, INK, self.px(c), 4)
            tail = c + c / max(float(np.linalg.norm(c)), 1e-12) * 0.6 * R * device["tongue_force"] / self.max_force_N
            pg.draw.line(self.screen, INK, self.px(tail), self.px(c), 2)
        self._scale_bar()
        self._draw_labels()
        self.screen.set_clip(None)
        return view_pct

    def _scale_bar(self) -> None:
        """A bar of a round length in the side view's lower left corner: the view is to scale, so say which."""
        mm = next(n for n in SCALE_BAR_MM if n * 1e-3 * self.scale >= 60)
        length = int(round(mm * 1e-3 * self.scale))
        x, y = SIDE[0] + 16, SIDE[1] + SIDE[3] - 16
        self.pg.draw.line(self.screen, INK, (x, y), (x + length, y), 3)
        for end in (x, x + length):
            self.pg.draw.line(self.screen, INK, (end, y - 6), (end, y + 1), 2)
        self.drawn["scale bar"] = (x, y - 1, length, 3)
        self._text(f"{mm} mm", (x + length + 8, y - 9), 18, name="scale bar label")

    def _solid(self, vertices: np.ndarray) -> None:
        pg = self.pg
        self._panel(SOLID, "Tongue, seen from the mouth")
        x0, y0, w, h = SOLID
        centre, scale = (x0 + w / 2, y0 + 20 + (h - 60) / 2), 0.36 * w

        def screen_of(points2: np.ndarray) -> np.ndarray:
            return np.column_stack([centre[0] + scale * points2[..., 0].ravel(),
                                    centre[1] - scale * points2[..., 1].ravel()]).reshape(*points2.shape[:-1], 2)

        error_mm = np.linalg.norm(vertices - self.target, axis=1) * self.radius * 1e3
        faces, colours = shaded_faces(vertices, self.triangles, error_mm, self.view3d, ramp, 0.0, self.error_top_mm)
        for face, colour in zip(screen_of(faces), (colours[:, :3] * 255).astype(int)):
            pg.draw.polygon(self.screen, colour, face)
        self._mesh.fill((0, 0, 0, 0))                     # the target's mesh half transparent over the tongue
        for (p, q) in screen_of(visible_edges(self.target, self.triangles, self.view3d)) - (x0, y0):
            pg.draw.line(self._mesh, (*TARGET, 110), p, q, 1)
        self.screen.blit(self._mesh, (x0, y0))
        self.drawn["target wireframe"] = (x0 + 10, y0 + 24, w - 20, h - 60)
        bar = (x0 + 20, y0 + h - 30)
        self.screen.blit(self._colour_bar, bar)
        self._text("distance to go: 0 mm", (bar[0], bar[1] + 12), 18)
        self._text(f"{self.error_top_mm:.1f} mm", (bar[0] + w - 84, bar[1] + 12), 18)
        self._text("green mesh: target", (x0 + w - 130, y0 + 24), 18, colour=TARGET)

    def _gauges(self, info: dict[str, Any], device: dict[str, Any]) -> None:
        self._panel(GAUGES, "Forces (N)")
        x0, y0 = GAUGES[0] + 14, GAUGES[1] + 34
        hand = float(np.linalg.norm(info["haptic_force_N"])) if "haptic_force_N" in info else 0.0
        gauges = [("tongue", "tongue", device["tongue_force"], self.max_force_N, self.safe_N, f"safe {self.safe_N:g}",
                   (200, 80, 90)),
                  ("incisors", "incisors", device["incisor_force"], 2 * self.incisor_limit_N, self.incisor_limit_N,
                   f"limit {self.incisor_limit_N:g}", (200, 120, 40)),
                  ("hand", "hand (rendered)", hand, 2 * self.incisor_limit_N, None, "", HAND)]
        for i, (key, label, value, top, limit, limit_label, colour) in enumerate(gauges):
            self.last_forces[key] = value
            self._gauge(f"gauge:{label}", label, value, top, limit, limit_label, colour, (x0, y0 + 86 * i))

    def _gauge(self, name: str, label: str, value: float, top: float, limit: float | None, limit_label: str,
               colour: tuple[int, int, int], at: tuple[int, int]) -> None:
        pg = self.pg
        x, y = at
        width = GAUGES[2] - 40
        over = limit is not None and value > limit
        self._text(f"{label}: {value:5.1f} N", (x, y), 24, colour=DANGER if over else INK)
        pg.draw.rect(self.screen, (228, 228, 228), (x, y + 22, width, 18))
        filled = int(width * min(max(value, 0.0) / top, 1.0))
        pg.draw.rect(self.screen, DANGER if over else colour, (x, y + 22, filled, 18))
        self.drawn[name] = (x, y + 22, filled, 18)
        step = _tick_step(top)
        for k in range(int(top / step + 1e-9) + 1):
            tx = x + int(width * k * step / top)
            pg.draw.line(self.screen, INK, (tx, y + 40), (tx, y + 45), 1)
            self._text(f"{k * step:g}", (tx - 6, y + 47), 18)
        if limit is not None:
            lx = x + int(width * limit / top)
            pg.draw.line(self.screen, DANGER, (lx, y + 18), (lx, y + 44), 3)
            self._text(limit_label, (lx - 22, y + 61), 18, colour=DANGER, name=f"{name} limit")

    def _status(self, info: dict[str, Any], view_pct: float, step: int, steps: int, dt: float) -> None:
        pg = self.pg
        self._panel(STATUS, "Progress")
        x, y = STATUS[0] + 14, STATUS[1] + 34
        width = STATUS[2] - 28
        error = info.get("shape_error_mm")
        on = bool(info.get("is_success"))
        text = ("shape error: move the hand to begin" if error is None else
                f"shape error {error:.2f} mm; on target under {self.success_mm:.2f} mm"
                + ("  ON TARGET" if on else ""))
        self._text(text, (x, y), 26, colour=TARGET if on else INK, name="shape error")
        rest = self.error_top_mm
        share = 0.0 if error is None else float(np.clip(1.0 - error / rest, 0.0, 1.0))
        pg.draw.rect(self.screen, (228, 228, 228), (x, y + 24, width, 14))
        pg.draw.rect(self.screen, TARGET, (x, y + 24, int(width * share), 14))
        goal = x + int(width * float(np.clip(1.0 - self.success_mm / rest, 0.0, 1.0)))
        pg.draw.line(self.screen, INK, (goal, y + 20), (goal, y + 42), 2)
        self._text(f"view of the glottis {view_pct:.0f} %", (x, y + 56), 26)
        self._text(f"time {step * dt:.2f} / {steps * dt:.2f} s", (x, y + 90), 26)
        pg.draw.rect(self.screen, (228, 228, 228), (x, y + 114, width, 8))
        pg.draw.rect(self.screen, (120, 120, 130), (x, y + 114, int(width * step / max(steps, 1)), 8))

    def _help(self) -> None:
        self._panel(HELP, "Controls")
        x0, y0 = HELP[0] + 14, HELP[1] + 30
        for i, (key, what) in enumerate(CONTROLS):
            column, row = divmod(i, 3)
            x, y = x0 + 420 * column, y0 + 22 * row
            self._text(key, (x, y), 20)
            self._text(what, (x + 105, y), 20, name=f"control:{key}")

    # -- helpers ---------------------------------------------------------------------------------------
    def _fit_side_view(self, env: Any) -> None:
        """Scale and place the side view so the tongue, eye, glottis and the whole laryngoscope at every
        pose of the hand's workspace fit inside it."""
        params = env.device.laryngoscope.params
        (xl, zl, pl, _), (xh, zh, ph, _) = params.hand_box
        device = env.device.drawing()
        hx, hz, _ = device["hand"]
        body = np.vstack([device["outline"], device["handle"]]) - (hx, hz)
        points = [np.array([[xl, zl], [xl, zh], [xh, zl], [xh, zh]])]
        for angle in np.linspace(pl, ph, 9):
            c, s = math.cos(angle), math.sin(angle)
            turned = body @ np.array([[c, s], [-s, c]])
            points += [turned + corner for corner in points[0]]
        R = self.radius
        points.append(np.array([[-1.1 * R, -1.1 * R], [1.1 * R, 1.1 * R], np.array(clinical.EYE) * R,
                                [clinical.GLOTTIS_X * R - 0.1 * R, clinical.GLOTTIS_Z[1] * R + 0.3 * R]]))
        allp = np.vstack(points)
        lo, hi = allp.min(axis=0), allp.max(axis=0)
        x0, y0, w, h = SIDE
        self.scale = 0.94 * min(w / (hi[0] - lo[0]), (h - 30) / (hi[1] - lo[1]))
        mid = (lo + hi) / 2
        self.origin = (x0 + w / 2 - self.scale * mid[0], y0 + 30 + (h - 30) / 2 + self.scale * mid[1])

    def px(self, p: Any) -> tuple[int, int]:
        """Side-view metres (x toward the mouth, z up) -> screen pixels."""
        return int(round(self.origin[0] + self.scale * p[0])), int(round(self.origin[1] - self.scale * p[1]))

    def pxs(self, points: Any) -> list[tuple[int, int]]:
        """:meth:`px` of each row of ``points`` ``(n, 2)``."""
        xy = np.rint(np.asarray(points, dtype=np.float64) * (self.scale, -self.scale) + self.origin).astype(int)
        return [(int(x), int(y)) for x, y in xy]

    def _bbox(self, points: Any) -> Rect:
        xy = np.array(self.pxs(points))
        (x0, y0), (x1, y1) = xy.min(axis=0), xy.max(axis=0)
        return int(x0), int(y0), int(x1 - x0) + 1, int(y1 - y0) + 1

    def _panel(self, rect: Rect, title: str) -> None:
        self.pg.draw.rect(self.screen, PANEL, rect)
        self.pg.draw.rect(self.screen, (200, 200, 205), rect, 1)
        self._text(title, (rect[0] + 8, rect[1] + 6), 22)

    def _card(self, rect: Rect) -> Rect:
        self.screen.blit(self._shade, (0, 0))
        self.pg.draw.rect(self.screen, PANEL, rect, border_radius=10)
        self.pg.draw.rect(self.screen, (90, 90, 100), rect, 2, border_radius=10)
        return rect

    def font(self, size: int) -> Any:
        """pygame's default font at ``size`` px (made once)."""
        if size not in self.fonts:
            self.fonts[size] = self.pg.font.Font(None, size)
        return self.fonts[size]

    def _text(self, text: str, at: tuple[float, float], size: int, colour: tuple[int, int, int] = INK,
              name: str | None = None) -> Rect:
        surface = self.font(size).render(text, True, colour)
        rect = self.screen.blit(surface, (int(at[0]), int(at[1])))
        out = (rect.x, rect.y, rect.w, rect.h)
        if name is not None:
            self.drawn[name] = out
        return out

    def _label(self, text: str, at: Any, offset: tuple[int, int], colour: tuple[int, int, int] = INK,
               name: str | None = None, on_shape: bool = False) -> None:
        """A side-view label at ``at`` (metres) + ``offset`` (px), drawn over everything else; unless
        ``on_shape``, moved to the nearest blank place around ``at`` when the offset lands on a drawing."""
        self._labels.append((text, at, offset, colour, name, on_shape))

    def _draw_labels(self) -> None:
        for text, at, offset, colour, name, on_shape in self._labels:
            x, y = self.px(at)
            w, h = self.font(20).size(text)
            place = (x + offset[0], y + offset[1])
            if not on_shape and not self._blank((*place, w, h)):
                place = next((c for c in _around((x, y), w, h) if self._blank((*c, w, h))), place)
                if math.dist((x, y), (place[0] + w / 2, place[1] + h / 2)) > 0.5 * w + 20:
                    near = (min(max(x, place[0] - 3), place[0] + w + 2), min(max(y, place[1] - 3), place[1] + h + 2))
                    self.pg.draw.line(self.screen, (150, 150, 150), (x, y), near, 1)   # a leader to what it names
            self._text(text, place, 20, colour, name or f"label:{text}")
        self._labels = []

    def _blank(self, rect: Rect) -> bool:
        """Whether ``rect`` lies inside the side view on nothing but its white panel (labels drawn so far included)."""
        x, y, w, h = rect
        if x < SIDE[0] + 2 or y < SIDE[1] + 30 or x + w > SIDE[0] + SIDE[2] - 2 or y + h > SIDE[1] + SIDE[3] - 24:
            return False
        pixels = self.pg.surfarray.pixels3d(self.screen)[x:x + w, y:y + h]
        return bool((pixels == PANEL).all())

    def _wrapped(self, text: str, at: tuple[int, int], width: int, size: int, name: str | None = None) -> int:
        """Draw ``text`` wrapped to ``width`` px; returns the y below it."""
        font, (x, y) = self.font(size), at
        line, rects = "", []
        for word in text.split():
            trial = f"{line} {word}".strip()
            if line and font.size(trial)[0] > width:
                rects.append(self._text(line, (x, y), size))
                y, line = y + font.get_linesize(), word
            else:
                line = trial
        if line:
            rects.append(self._text(line, (x, y), size))
            y += font.get_linesize()
        if name is not None and rects:
            self.drawn[name] = (x, rects[0][1], max(r[2] for r in rects), y - rects[0][1])
        return y

    def _dashed(self, points: np.ndarray, colour: tuple[int, int, int], width: int, dash_px: float = 7.0) -> None:
        """A closed dashed line through ``points`` (metres): dashes and gaps of ``dash_px``."""
        closed = np.array(self.pxs(np.vstack([points, points[:1]])), dtype=np.float64)
        length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
        for start in np.arange(0.0, length[-1], 2 * dash_px):
            ends = [(float(np.interp(d, length, closed[:, 0])), float(np.interp(d, length, closed[:, 1])))
                    for d in (start, min(start + dash_px, length[-1]))]
            self.pg.draw.line(self.screen, colour, ends[0], ends[1], width)


def _around(at: tuple[int, int], w: int, h: int) -> list[tuple[int, int]]:
    """Top-left corners of a ``w`` x ``h`` label around ``at``, nearest first: right, left, above, below and
    the corners, at growing gaps."""
    x, y = at
    out = []
    for gap in (8, 20, 36, 56, 80):
        out += [(x + gap, y - h // 2), (x - gap - w, y - h // 2), (x - w // 2, y - gap - h), (x - w // 2, y + gap),
                (x + gap, y - gap - h), (x - gap - w, y - gap - h), (x + gap, y + gap), (x - gap - w, y + gap)]
    return out


def _by_angle(profile: np.ndarray) -> np.ndarray:
    """A section's points (each edge's crossing appears once per triangle) once each, ordered around the
    centre: a polygon."""
    profile = np.unique(profile, axis=0)
    return profile[np.argsort(np.arctan2(profile[:, 1], profile[:, 0]))]


def _tick_step(top: float) -> float:
    """A round tick spacing giving 4 to 10 ticks over ``[0, top]``."""
    step = 10.0 ** math.floor(math.log10(top / 4.0))
    for factor in (1.0, 2.0, 5.0, 10.0):
        if top / (step * factor) <= 10.0:
            return step * factor
    return step * 10.0
