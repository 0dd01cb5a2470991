"""``softenv play``: a person drives the simulated laryngoscope, sees the tongue, the target and the blade,
reads the forces on gauges, and is scored on the recorded device log.

The window is pygame's (SDL): a real event loop at the control rate, keyboard, mouse and gamepads
(``pygame.joystick``) in one API, drawing a frame in a few milliseconds, and a dummy video driver
(``SDL_VIDEODRIVER=dummy``) that runs the same code headless. matplotlib's interactive backends redraw
at 20-30 frames per second and need a GUI toolkit, too slow for a 50 Hz device.

A session: a start screen states the task and the controls (:data:`softenv.training.inputs.CONTROLS`)
and waits for Space, Enter or a click; then the scene (SoftSphereHaptic-v0's, or an airway grade's: the
title names it) runs toward the family-centre
target (the one trainee scoring uses) for ``seconds``, one frame per control period
(:mod:`softenv.training.play_view`), Space or P pausing it and Esc ending it early; the hand's pose is
recorded every control period as a device log (:data:`softenv.training.logs.HAND_LOG`, with what the
device's sensors read: the tongue's force on the blade and the blade's height), written, and
scored with :func:`softenv.training.scoring.score_file`, which replays the log through the same
physics: the score is the session's own (tested). An end screen shows the score, each part against
the expert's and the two things to improve first, and stays until the window is closed.
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

from ..airway import scene_title
from ..envs.config import scene_sections
from ..haptics.arms import BACKENDS
from ..haptics.bridge import LOOPBACK, BridgeServer
from ..sections import SceneConfig
from .hand import hand_config, haptic_config, reach_env, relative_hand_pose, sensor_readings, workspace
from .inputs import ArmInput, BridgeInput, InputDevice, PygameInput
from .logs import HAND_LOG, SENSOR_COLUMNS, read_log, save_log
from .play_view import SIZE, PlayView
from .scoring import INCISOR_LIMIT_N, score_log

SCREEN_FPS = 30.0                     # the start and end screens' redraw rate in real time


@dataclass
class Session:
    """What a session leaves: the device log (and where it was written), the live episode's last info, the
    score report."""

    log: np.ndarray
    log_path: Path
    live_final_error_mm: float
    live_clinical: dict[str, float]
    report: dict[str, Any] = field(default_factory=dict)


def run(seconds: float = 10.0, out_dir: str | Path = "play", scene: dict[str, Any] | None = None,
        realtime: bool = True, script: Callable[[int], list[Any]] | None = None,
        echo: Callable[[str], None] = print, bridge: BridgeServer | None = None, screens: bool = True,
        device: InputDevice | None = None, on_frame: Callable[[int, str, PlayView], None] | None = None) -> Session:
    """Play one session of ``seconds``; write ``<out_dir>/session_<time>.csv`` and its score report.

    The hand follows ``device`` (:mod:`softenv.training.inputs`; default: keys, mouse and gamepad), or
    with ``bridge`` a device process on the network bridge (each control period the hand moves toward
    the newest pose it sent and the rendered force goes back; with ``realtime=False`` the session waits
    up to a second each period for the device's next pose: lockstep). The log's comment line names the
    device, and for the bridge how many messages were accepted, garbled, out of range, late or from
    another sender.

    ``screens=False`` skips the start screen and closes after the session instead of holding the end
    screen (``--headless``: scripted sessions, servers). ``script(frame)`` returns pygame events to post
    before each frame (a scripted player; with ``screens=False`` frame ``k`` is control period ``k``);
    ``on_frame(frame, phase, view)`` is called after each frame is drawn, ``phase`` one of ``start``,
    ``run``, ``paused``, ``end``; ``realtime=False`` steps as fast as it can.
    """
    import pygame                       # the play extra: only for a session

    sections = scene_sections(scene)
    config = haptic_config(sections)                 # the session's scene, made once: the env and the scoring take it
    dt = config["dynamics"]["dt"]
    steps = max(1, int(round(seconds / dt)))
    env = reach_env(config, steps)
    world = env.world
    env.reset(seed=0, options={"target": world.force_box.normalised(world.family.centre)})
    # the display and fonts only (joysticks in PygameInput): pygame.init() would also open the mixer, whose
    # ALSA back end prints a page of errors on machines without sound, and a session makes no sound
    pygame.display.init()
    pygame.font.init()
    frame = 0

    def next_events() -> list[Any]:
        nonlocal frame
        for event in (script(frame) if script else []):
            pygame.event.post(event)
        frame += 1
        return pygame.event.get()

    def shown(phase: str, view: PlayView) -> None:
        pygame.display.flip()
        if on_frame is not None:
            on_frame(frame - 1, phase, view)

    try:
        screen = pygame.display.set_mode(SIZE)
        pygame.display.set_caption(f"softenv play: {scene_title(config['airway'])}")
        view = PlayView(pygame, screen, env, INCISOR_LIMIT_N)
        hand = device if device is not None else (
            BridgeInput(bridge, 0.0 if realtime else 1.0) if bridge is not None else PygameInput(pygame))
        poses = [relative_hand_pose(env)]
        readings = [sensor_readings(env)]               # the log's sensor columns, a row each
        info: dict[str, Any] = {}
        quit_ = screens and _start_screen(pygame, view, env, next_events, shown, realtime)
        paused, step, started = False, 0, time.perf_counter()
        while not quit_ and step < steps:
            for event in next_events():
                if _is_quit(pygame, event):
                    quit_ = True
                elif event.type == pygame.KEYDOWN and event.key in (pygame.K_SPACE, pygame.K_p):
                    paused = not paused
                hand.handle(event)
            if quit_:
                break
            if paused:
                view.frame(env, info, step, steps, dt)
                view.paused()
                shown("paused", view)
                if realtime:
                    time.sleep(dt)
                    started += dt                   # a pause does not count against the session's clock
                continue
            _, _, _, _, info = env.step(hand.action(env, dt))
            step += 1
            hand.feel(step, step * dt, info["haptic_force_N"])
            poses.append(relative_hand_pose(env))
            readings.append(sensor_readings(env))
            view.frame(env, info, step, steps, dt)
            shown("run", view)
            if realtime:
                time.sleep(max(0.0, started + step * dt - time.perf_counter()))
        if len(poses) < 2:
            raise ValueError("the session ended before its first control period; nothing to score")
        if screens:
            view.frame(env, info, step, steps, dt)
            view.message("Scoring the session ...")
            pygame.display.flip()
        log = np.column_stack([np.arange(len(poses)) * dt, np.array(poses)])
        out = Path(out_dir)
        path = out / f"session_{time.strftime('%Y%m%d-%H%M%S')}.csv"
        save_log(log, path, HAND_LOG, note=f"softenv play, {scene_title(config['airway'])}, {len(poses) - 1} steps of {dt:g} s, "
                 f"driven by {hand.describe()}", scene=scene,
                 readings={c: np.array([r[c] for r in readings]) for c in SENSOR_COLUMNS})
        live = env.device.clinical_summary(env.b)
        _, logged = read_log(path, HAND_LOG)         # scored as written (9 digits), as `softenv score` of the file is
        report = score_log(logged, HAND_LOG, config, path, sections, "the log", out)
        echo(f"wrote {path}; score {report['score']:.1f}/100 ("
             + ", ".join(f"{k} {report[k]:.2f}" for k in report["weights"]) + f"); report in {out}/{path.stem}_score.md")
        for i, line in enumerate(report["advice"]):
            echo(f"  to improve ({i + 1}): {line}")
        if screens:
            written = f"{path} and {path.stem}_score.md, .json, .png"
            done = False
            while not done:
                done = any(_is_quit(pygame, e) or (e.type == pygame.KEYDOWN and e.key == pygame.K_RETURN)
                           for e in next_events())
                view.end_screen(env, info, step, steps, dt, report, report["advice"], written)
                shown("end", view)
                if realtime:
                    time.sleep(1.0 / SCREEN_FPS)
        if device is None:
            hand.close()
    finally:
        pygame.quit()
    return Session(log, path, float(info.get("shape_error_mm", math.nan)), live, report)


def _start_screen(pygame: Any, view: PlayView, env: Any, next_events: Callable[[], list[Any]],
                  shown: Callable[[str, PlayView], None], realtime: bool) -> bool:
    """Show the task until Space, Enter or a click (returns False) or until the window is closed or Esc (True)."""
    while True:
        for event in next_events():
            if _is_quit(pygame, event):
                return True
            if (event.type == pygame.KEYDOWN and event.key in (pygame.K_SPACE, pygame.K_RETURN, pygame.K_p)) \
                    or (event.type == pygame.MOUSEBUTTONDOWN and event.button == 1):
                return False
        view.start_screen(env)
        shown("start", view)
        if realtime:
            time.sleep(1.0 / SCREEN_FPS)


def _is_quit(pygame: Any, event: Any) -> bool:
    return bool(event.type == pygame.QUIT or (event.type == pygame.KEYDOWN and event.key == pygame.K_ESCAPE))


def open_bridge(host: str = LOOPBACK, port: int = 0, config: SceneConfig | None = None) -> BridgeServer:
    """A bridge for a device to drive a session on ``config`` (None: SoftSphereHaptic-v0's), its poses checked
    against the hand's workspace; refused in one line if the address cannot be bound."""
    try:
        return BridgeServer(workspace(hand_config(config)), host, port)
    except OSError as exc:
        raise ValueError(f"--bridge {host}:{port} cannot be listened on: {exc.strerror or exc}") from None


def open_haptic_device(kind: str, config: SceneConfig | None = None) -> ArmInput:
    """A vendor haptic arm (``touch`` or ``forcedimension``: :mod:`softenv.haptics.arms`) mapped
    into the hand's workspace on ``config`` (None: SoftSphereHaptic-v0's); refused in one line naming what to install if it cannot open."""
    if kind not in BACKENDS:
        raise ValueError(f"--device {kind!r} is not one of {['keys', *BACKENDS]}")
    return ArmInput(BACKENDS[kind](workspace(hand_config(config))))


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
