"""Benchmark of ``softenv play``'s window: frames per second of a session's loop (one control step and
one frame drawn), headless on SDL's dummy video driver (:mod:`softenv.training.play_view`)."""

from __future__ import annotations

import time

import numpy as np

from ..training import play
from ..training.hand import haptic_config, reach_env
from ..training.play_view import SIZE, PlayView
from ..training.scoring import INCISOR_LIMIT_N
from .timing import Row, Timing


def bench_play(quick: bool, reference: Timing) -> list[Row]:
    """Random actions on SoftSphereHaptic-v0's scene, each step drawn as ``softenv play`` draws it. The dummy
    driver draws into memory as a window does, but shows nothing: a real display adds the copy to the screen."""
    import pygame                                   # the play extra

    frames = 150 if quick else 1_000
    play.headless()
    env = reach_env(haptic_config(None), frames)
    world = env.world
    env.reset(seed=0, options={"target": world.force_box.normalised(world.family.centre)})
    pygame.display.init()
    pygame.font.init()
    try:
        view = PlayView(pygame, pygame.display.set_mode(SIZE), env, INCISOR_LIMIT_N)
        actions = np.random.default_rng(0).uniform(-1, 1, (frames, 4)).astype(np.float32)
        loop, draw = [], []
        for k in range(frames):
            started = time.perf_counter()
            _, _, _, _, info = env.step(actions[k])
            drawn = time.perf_counter()
            view.frame(env, info, k + 1, frames, 0.02)
            pygame.display.flip()
            done = time.perf_counter()
            loop.append(done - started)
            draw.append(done - drawn)
    finally:
        pygame.quit()
    fps = 1.0 / np.array(loop)
    rate = 1.0 / world.config["dynamics"]["dt"]
    return [
        Row("play", f"session loop: a control step and its frame drawn, frames/s ({frames} frames, {SIZE[0]}x{SIZE[1]})",
            float(np.median(fps)), "frames/s", f"IQR {np.percentile(fps, 25):.0f}-{np.percentile(fps, 75):.0f}; "
            f"drawing alone {1e3 * np.median(draw):.1f} ms", f">= 30 frames/s; >= {rate:g} keeps the control rate",
            bool(np.median(fps) >= 30.0)),
        Row("play", "session loop, slowest tenth of frames", float(np.percentile(fps, 10)), "frames/s",
            f"min {fps.min():.0f}", ">= 30 frames/s", bool(np.percentile(fps, 10) >= 30.0)),
    ]
