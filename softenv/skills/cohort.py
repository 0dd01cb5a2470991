"""A demo cohort: synthetic trainees of the published profiles, learning over weekly sessions.

Twelve trainees start at the published profiles (:mod:`softenv.training.profiles`: three each of
``novice``, ``novice (time)``, ``novice (force)`` and ``intermediate``), each with its profile's error
amounts times a factor in [0.8, 1.2]. Practice shrinks every error by the **power law of practice**
(Newell & Rosenbloom 1981, "Mechanisms of skill acquisition and the law of practice"): in session
``n`` an error is ``amount_1 n^-alpha``, with a learning rate ``alpha`` drawn per trainee from [0.8, 1.6]
(no study reports the exponent for these errors; a stated choice, so that within ten sessions some
trainees reach the pass mark and some do not: the score falls steeply with the press's overshoot),
times a session's own variation (a log-normal factor of spread 0.15), on top of the physiological
tremor and hesitation every member of :mod:`softenv.skills.passmark`'s groups shows. Sessions are a
week apart. Each session's log is the scripted expert's hand log degraded by those amounts
(:func:`softenv.training.trainee.degrade`), kept and scored as any other (source ``demo``), and the
scene's pass mark is set by the contrasting-groups method.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Callable

import numpy as np

from .. import __version__
from .._cache import cache_dir
from .._validation import check_int
from ..baselines.run_store import code_digest
from ..training import scoring
from ..training.logs import HAND_LOG, save_log
from ..training.trainee import degrade, expert_hand_log
from .passmark import contrasting_groups, profile_amounts, with_baseline
from .store import Store, scene_name

STARTING_PROFILES = ("novice", "novice (time)", "novice (force)", "intermediate")
FIRST_SESSION = datetime(2026, 9, 7, 9, 0, tzinfo=timezone.utc)
SESSION_SPREAD = 0.15                 # a session's own variation of each error (log-normal spread)


def plan(trainees: int = 12, sessions: int = 10, seed: int = 0) -> list[tuple[str, str, int, datetime, dict[str, float], int]]:
    """The cohort's sessions, in order: (trainee, starting profile, session number, when, error amounts, tremor seed)."""
    check_int(trainees, "trainees", 1, 200)
    check_int(sessions, "sessions", 1, 100)
    rng = np.random.default_rng(seed)
    starts = {name: profile_amounts(name) for name in STARTING_PROFILES}
    out = []
    for t in range(trainees):
        profile = STARTING_PROFILES[t % len(STARTING_PROFILES)]
        first = {k: v * rng.uniform(0.8, 1.2) for k, v in starts[profile].items()}
        alpha = rng.uniform(0.8, 1.6)
        offset = timedelta(hours=int(rng.integers(0, 8)), days=int(rng.integers(0, 5)))
        for n in range(1, sessions + 1):
            amounts = with_baseline({k: v * n ** -alpha * rng.lognormal(0.0, SESSION_SPREAD) for k, v in first.items()},
                                    rng)
            when = FIRST_SESSION + offset + timedelta(weeks=n - 1)
            out.append((f"T-{t + 1:02d}", profile, n, when, amounts, int(rng.integers(1 << 31))))
    return out


def build(store: Store, trainees: int = 12, sessions: int = 10, seed: int = 0, per_group: int = 20,
          progress: Callable[[str, int, int], None] | None = None) -> None:
    """Keep the demo cohort's sessions in ``store`` and set the scene's pass mark (``progress(stage, done, total)``)."""
    expert_log = expert_hand_log()
    rows = plan(trainees, sessions, seed)
    with tempfile.TemporaryDirectory(prefix="softenv-demo-") as folder:
        for i, (trainee, profile, n, when, amounts, tremor_seed) in enumerate(rows):
            path = Path(folder) / f"{trainee}_session{n:02d}.csv"
            save_log(degrade(expert_log, None, seed=tremor_seed, **amounts), path, HAND_LOG,
                     note=f"softenv demo cohort: {trainee}, starting profile {profile}, session {n}")
            store.add(path, trainee, recorded_at=when, source="demo")
            if progress is not None:
                progress("sessions", i + 1, len(rows))
    mark = contrasting_groups(scene_name(HAND_LOG.name, {}), None, per_group, seed,
                              None if progress is None else lambda d, t: progress("pass mark", d, t))
    store.set_pass_mark(mark)


def demo_store(trainees: int = 12, sessions: int = 10, seed: int = 0,
               progress: Callable[[str, int, int], None] | None = None) -> Path:
    """The demo cohort's SQLite file in softenv's cache, built on first use (about a minute; made
    aside and moved into place, so a reader never sees half of it). Rebuilt when softenv's code changes
    (the simulator that plays the sessions as much as the score's formula)."""
    key = json.dumps({"trainees": trainees, "sessions": sessions, "seed": seed, "version": __version__,
                      "formula": scoring.SCORE_VERSION, "code": code_digest()}, sort_keys=True)
    path = cache_dir() / f"skills-demo-{hashlib.sha256(key.encode()).hexdigest()[:16]}.sqlite"
    if path.exists():
        return path
    fd, partial = tempfile.mkstemp(prefix=path.stem, suffix=".partial", dir=path.parent)
    os.close(fd)
    os.unlink(partial)
    try:
        with Store(partial) as store:
            build(store, trainees, sessions, seed, progress=progress)
        os.replace(partial, path)
    finally:
        if os.path.exists(partial):
            os.unlink(partial)
    return path
