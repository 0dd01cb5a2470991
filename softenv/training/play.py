"""``softenv play``: a person drives the simulated laryngoscope, sees the tongue and blade, feels the
force as a gauge, and is scored on the recorded device log.

The window is pygame's (SDL): a real event loop at the control rate, keyboard, mouse and gamepads
(``pygame.joystick``) in one API, drawing in well under a millisecond a frame, and a dummy video
driver (``SDL_VIDEODRIVER=dummy``) that runs the same code headless. matplotlib's interactive
backends redraw at 20-30 frames per second and need a GUI toolkit, too slow for a 50 Hz device.

Controls (the action of SoftSphereHaptic-v0, held while the key is down):

| input | action |
|---|---|
| Left / Right arrow | insert along the blade / withdraw |
| Down / Up arrow | lift along the handle (press into the tongue) / ease off |
| D / A | sweep right (+y) / left |
| E / Q | tip the blade down / up (wrist pitch) |
| left mouse button held | a virtual joystick: the drag from where it was pressed sets insert and lift (60 px = full speed) |
| gamepad | left stick: insert and lift; right stick: sweep and pitch |
| Esc or closing the window | end the session early |

The session runs SoftSphereHaptic-v0's scene toward the family-centre target (the one trainee
scoring uses), records the hand's pose every control period as a device log
(:data:`softenv.training.logs.HAND_LOG`), writes it, and scores it with :func:`softenv.training.scoring.score_file`,
which replays the log through the same physics: the score is the session's own (tested).
"""

from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .. import clinical
from .bridge import LOOPBACK, BridgeServer
from .hand import action_toward, haptic_config, haptic_env, relative_hand_pose, workspace
from .logs import HAND_LOG, save_log
from .scoring import score_file

SIZE = (960, 540)
SCALE = 2600.0                        # px per metre in the side view
ORIGIN = (300, 300)                   # the tongue's centre on screen
KEYS = {"insert": ("K_LEFT", "K_RIGHT"), "press": ("K_DOWN", "K_UP"), "sweep": ("K_d", "K_a"), "pitch": ("K_e", "K_q")}
DRAG_FULL_PX = 60.0


@dataclass
class Session:
    """What a session leaves: the device log, the live episode's last info, the score report."""

    log: np.ndarray
    live_final_error_mm: float
    live_clinical: dict[str, float]
    report: dict[str, Any] = field(default_factory=dict)


class Controls:
    """Keyboard, mouse and gamepad state -> an action in [-1, 1]^4 (see the module docstring)."""

    def __init__(self, pygame: Any) -> None:
        self.pg = pygame
        self.down: set[int] = set()
        self.drag_from: tuple[int, int] | None = None
        self.mouse = (0, 0)
        self.quit = False
        pygame.joystick.init()
        self.pads = [pygame.joystick.Joystick(i) for i in range(pygame.joystick.get_count())]

    def handle(self, event: Any) -> None:
        pg = self.pg
        if event.type == pg.QUIT or (event.type == pg.KEYDOWN and event.key == pg.K_ESCAPE):
            self.quit = True
        elif event.type == pg.KEYDOWN:
            self.down.add(event.key)
        elif event.type == pg.KEYUP:
            self.down.discard(event.key)
        elif event.type == pg.MOUSEBUTTONDOWN and event.button == 1:
            self.drag_from = self.mouse = event.pos
        elif event.type == pg.MOUSEBUTTONUP and event.button == 1:
            self.drag_from = None
        elif event.type == pg.MOUSEMOTION:
            self.mouse = event.pos

    def action(self) -> np.ndarray:
        pg = self.pg
        a = np.zeros(4)
        for i, (plus, minus) in enumerate(KEYS.values()):
            a[i] = float(getattr(pg, plus) in self.down) - float(getattr(pg, minus) in self.down)
        if self.drag_from is not None:           # drag left = insert, drag down = lift
            a[0] += (self.drag_from[0] - self.mouse[0]) / DRAG_FULL_PX
            a[1] += (self.mouse[1] - self.drag_from[1]) / DRAG_FULL_PX
        for pad in self.pads:
            axes = [pad.get_axis(j) if j < pad.get_numaxes() else 0.0 for j in range(4)]
            a += [-axes[0], axes[1], axes[2], axes[3]]
        return np.clip(a, -1.0, 1.0)


def run(seconds: float = 10.0, out_dir: str | Path = "play", scene: dict[str, Any] | None = None,
        realtime: bool = True, script: Callable[[int], list[Any]] | None = None,
        echo: Callable[[str], None] = print, bridge: BridgeServer | None = None) -> Session:
    """Play one session of ``seconds``; write ``<out_dir>/session_<time>.csv`` and its score report.

    ``script(step)`` returns pygame events to post before each step (a scripted player, for tests and
    demos); ``realtime=False`` steps as fast as it can. With ``bridge`` (:mod:`softenv.training.bridge`)
    a device drives the hand instead of the keys: each control period the hand moves toward the newest
    pose it sent (held where it was if none came) and the rendered force goes back to it; with
    ``realtime=False`` the session waits up to a second each period for the device's next pose (lockstep).
    The log's comment line says how many of its messages were accepted, garbled, out of range, late or
    from another sender.
    """
    import pygame                       # the play extra: only for a session

    config = haptic_config(scene)
    dt = config["dynamics"]["dt"]
    steps = max(1, int(round(seconds / dt)))
    env = haptic_env(scene, steps)
    world = env.world
    env.reset(seed=0, options={"target": world.force_box.normalised(world.family.centre)})
    # the display and fonts only (joysticks in Controls): pygame.init() would also open the mixer, whose
    # ALSA back end prints a page of errors on machines without sound, and a session makes no sound
    pygame.display.init()
    pygame.font.init()
    try:
        screen = pygame.display.set_mode(SIZE)
        pygame.display.set_caption("softenv play: SoftSphereHaptic-v0")
        font = pygame.font.Font(None, 22)
        controls = Controls(pygame)
        poses, info = [relative_hand_pose(env)], {}
        goal, seq = poses[0], 0                        # a device's newest pose (the start until it sends one)
        started = time.perf_counter()
        for step in range(steps):
            for event in (script(step) if script else []):
                pygame.event.post(event)
            for event in pygame.event.get():
                controls.handle(event)
            if controls.quit:
                break
            if bridge is None:
                action = controls.action().astype(np.float32)
            else:
                sent = bridge.poll(0.0 if realtime else 1.0)
                if sent is not None:
                    goal, seq = sent.pose, sent.seq
                action = action_toward(env, goal)
            _, _, _, _, info = env.step(action)
            if bridge is not None:
                bridge.send_force(seq, (step + 1) * dt, info["haptic_force_N"])
            poses.append(relative_hand_pose(env))
            _draw(screen, font, env, info, step + 1, steps, dt)
            pygame.display.flip()
            if realtime:
                time.sleep(max(0.0, started + (step + 1) * dt - time.perf_counter()))
    finally:
        pygame.quit()
    if len(poses) < 2:
        raise ValueError("the session ended before its first control period; nothing to score")
    log = np.column_stack([np.arange(len(poses)) * dt, np.array(poses)])
    out = Path(out_dir)
    path = out / f"session_{time.strftime('%Y%m%d-%H%M%S')}.csv"
    by = "keys" if bridge is None else "a device over the bridge, messages " + ", ".join(
        f"{k} {v}" for k, v in bridge.counts.items())
    save_log(log, path, HAND_LOG, note=f"softenv play, SoftSphereHaptic-v0, {len(poses) - 1} steps of {dt:g} s, "
             f"driven by {by}", scene=scene)
    live = env.device.clinical_summary(env.b)
    report = score_file(path, scene, out)
    echo(f"wrote {path}; score {report['score']:.1f}/100 ("
         + ", ".join(f"{k} {report[k]:.2f}" for k in report["weights"]) + f"); report in {out}/{path.stem}_score.md")
    return Session(log, float(info.get("shape_error_mm", math.nan)), live, report)


def _draw(screen: Any, font: Any, env: Any, info: dict[str, Any], step: int, steps: int, dt: float) -> None:
    """The side view (tongue midline, blade, incisors, hand) and the gauges."""
    import pygame                                           # the play extra

    def px(x: float, y: float) -> tuple[int, int]:
        return int(ORIGIN[0] + SCALE * x), int(ORIGIN[1] - SCALE * y)

    world = env.world
    screen.fill((250, 248, 244))
    radius = world.config["tissue"]["radius"]
    vertices = world.vertices(env.b).reshape(-1, 3)             # in tongue radii
    profile = clinical.sagittal_profile(vertices, world.scene.mesh.triangles) * radius
    order = np.argsort(np.arctan2(profile[:, 1], profile[:, 0]))
    pygame.draw.polygon(screen, (232, 144, 154), [px(*p) for p in profile[order]])
    device = env.device.drawing()
    pygame.draw.polygon(screen, (120, 130, 140), [px(*p) for p in device["outline"]])
    pygame.draw.line(screen, (90, 90, 100), px(*device["handle"][0]), px(*device["handle"][1]), 8)
    (a, b), r = device["incisor"][:2], device["incisor"][2]
    pygame.draw.line(screen, (215, 205, 170), px(*a), px(*b), max(2, int(2 * r * SCALE)))
    pygame.draw.circle(screen, (200, 60, 60) if device["incisor_force"] > 0 else (160, 160, 150), px(*a),
                       max(2, int(r * SCALE)), 2)
    gx, gy, _ = device["hand"]
    pygame.draw.circle(screen, (40, 90, 200), px(gx, gy), 7)
    if device["contact"] is not None:
        pygame.draw.circle(screen, (30, 30, 30), px(*device["contact"]), 4)
    # gauges: what a person on a haptic device would feel, and the task's state
    dev = world.config["device"]
    safe = world.weights["safe_force"]
    bars = [("tongue force", info.get("tongue_force_N", 0.0), dev["max_normal_force"], safe, (200, 80, 90)),
            ("incisor force", info.get("incisor_force_N", 0.0), 20.0, 0.0, (200, 40, 40)),
            ("hand force (rendered)", float(np.linalg.norm(info.get("haptic_force_N", np.zeros(3)))), 20.0, None,
             (60, 110, 200))]
    x0 = 640
    for i, (label, value, top, mark, colour) in enumerate(bars):
        y = 60 + 70 * i
        pygame.draw.rect(screen, (225, 225, 225), (x0, y + 20, 280, 18))
        pygame.draw.rect(screen, colour, (x0, y + 20, int(280 * min(value / top, 1.0)), 18))
        if mark:
            pygame.draw.line(screen, (0, 0, 0), (x0 + int(280 * mark / top), y + 16), (x0 + int(280 * mark / top), y + 42), 2)
        screen.blit(font.render(f"{label}: {value:5.1f} N", True, (20, 20, 20)), (x0, y))
    view = clinical.glottic_view(profile, radius)
    lines = [f"shape error {info.get('shape_error_mm', 0.0):.2f} mm ({'on target' if info.get('is_success') else 'not yet'})",
             f"glottic view {view:.0f} %", f"time {step * dt:.2f} / {steps * dt:.2f} s",
             "arrows: insert / lift   A D: sweep   Q E: pitch   Esc: end"]
    for i, text in enumerate(lines):
        screen.blit(font.render(text, True, (20, 20, 20)), (x0, 290 + 28 * i))


def open_bridge(host: str = LOOPBACK, port: int = 0, scene: dict[str, Any] | None = None) -> BridgeServer:
    """A bridge for a device to drive a session on ``scene``, its poses checked against the hand's
    workspace; refused in one line if the address cannot be bound."""
    try:
        return BridgeServer(workspace(haptic_config(scene)), host, port)
    except OSError as exc:
        raise ValueError(f"--bridge {host}:{port} cannot be listened on: {exc.strerror or exc}") from None


def display_available() -> bool:
    """Whether a window can be shown: a desktop (macOS, Windows), an X or Wayland display, or an SDL
    video driver chosen on purpose (``SDL_VIDEODRIVER``; ``dummy`` for scripted sessions)."""
    if not sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd")):
        return True
    return any(os.environ.get(v) for v in ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER"))


def headless() -> None:
    """Use SDL's dummy video and audio drivers (no window; for tests and servers)."""
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
