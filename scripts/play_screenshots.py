"""Screenshots of ``softenv play`` for the README and the docs: the start screen, a frame mid-press and the
end screen of a scripted session (keys as a person presses them), drawn headless on SDL's dummy driver.

    python scripts/play_screenshots.py --out results

Writes ``play_start.png``, ``play_mid_press.png``, ``play_end.png`` and ``play_screenshots.txt`` (this
command, the code revision and what each shot shows); the session's own log and report go to a
temporary folder.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path
from typing import Any

import pygame

from softenv._artifact import atomic_write, write_text
from softenv.bench.timing import code_revision
from softenv.training import play
from softenv.training.play_view import PlayView

PRESS_START, PRESS_END = 32, 47            # frames: the start screen is frame 0, Space starts the session at 1


def key(k: int, down: bool = True) -> Any:
    return pygame.event.Event(pygame.KEYDOWN if down else pygame.KEYUP, key=k, mod=0)


# a trainee's first go: insert, lift (press) briefly, sweep aside, then let go; Space leaves the start screen
SCRIPT = {1: [key(pygame.K_SPACE)], 2: [key(pygame.K_LEFT)], PRESS_START: [key(pygame.K_LEFT, False), key(pygame.K_DOWN)],
          PRESS_END: [key(pygame.K_DOWN, False), key(pygame.K_d)], PRESS_END + 30: [key(pygame.K_d, False)]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results"))
    args = parser.parse_args()
    play.headless()
    shots: dict[str, Any] = {}
    lines: dict[str, str] = {}

    def on_frame(frame: int, phase: str, view: PlayView) -> None:
        name = {"start": "play_start", "end": "play_end"}.get(phase, "play_mid_press" if frame == PRESS_END else "")
        if name and name not in shots:
            shots[name] = view.screen.copy()
            lines[name] = f"{name}.png: frame {frame} ({phase}); drawn: {', '.join(sorted(k for k in view.drawn if not k.startswith('control:')))}"

    ended = PRESS_END + 200
    here = Path.cwd()
    with tempfile.TemporaryDirectory() as work:
        os.chdir(work)          # the end card names the report as a user's relative folder, not this machine's
        try:
            session = play.run(seconds=4.0, out_dir="sessions", realtime=False, on_frame=on_frame,
                               echo=lambda s: None,
                               script=lambda f: SCRIPT.get(f, []) + ([key(pygame.K_RETURN)] if f == ended else []))
        finally:
            os.chdir(here)
    for name, surface in shots.items():
        atomic_write(args.out / f"{name}.png", lambda fh, s=surface, n=name: pygame.image.save(s, fh, f"{n}.png"))
    score = session.report["score"]
    write_text(args.out / "play_screenshots.txt",
               f"made by: python scripts/play_screenshots.py --out {args.out} at {code_revision()}\n"
               f"session: 4 s scripted keys, score {score:.1f}/100\n" + "\n".join(lines[n] for n in sorted(lines)) + "\n")
    print(f"wrote {', '.join(f'{args.out}/{n}.png' for n in sorted(shots))}; session score {score:.1f}/100")


if __name__ == "__main__":
    main()
