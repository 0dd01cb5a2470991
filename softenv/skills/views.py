"""What the dashboard draws: plots as SVG text and a session's replay as an animated GIF.

Plots are matplotlib's (the project's drawing library, the ``viz`` extra), made with its object API
(no pyplot state, so that the server's threads can draw at once) and sent as SVG: sharp at any size,
no charting script in the browser. The replay renders the scene's own view
(:class:`softenv.envs.rendering.SceneRenderer`: the tongue and, for a hand log, the side view of blade,
incisors and hand) every few control periods of the replayed log, and Pillow (matplotlib's own image
library) encodes the frames as a GIF that any browser plays.
"""

from __future__ import annotations

import io
import math
import threading
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from PIL import Image

from ..training.logs import HAND_LOG, read_log
from ..training.scoring import replay, replay_hand, scene_of
from .passmark import PassMark
from .store import StoredSession, log_file

FRAMES = 30                     # frames in a replay's animation, whatever the session's length
PLAYBACK_S = 6.0                # how long one pass of the animation lasts
_RENDER = threading.Lock()      # the scene renderer draws through pyplot, which is not thread-safe

# the clinical metrics a trainee's page plots, with their units (the keys of softenv.devices.laryngoscope.clinical's summary)
METRIC_LABELS = {
    "peak_tongue_force_N": "peak tongue force (N)", "mean_tongue_force_N": "mean tongue force (N)",
    "tongue_force_time_Ns": "tongue force-time (N s)", "peak_incisor_force_N": "peak incisor force (N)",
    "incisor_contact_s": "incisor contact (s)", "peak_jaw_force_N": "peak jaw force (N)", "lever_share": "lever share", "hand_path_m": "hand path (m)",
    "sparc": "SPARC", "ldlj": "LDLJ", "glottic_view_pct": "glottic view (%)", "duration_s": "duration (s)",
    "final_error_mm": "final shape error (mm)", "time_to_target_s": "time to target (s)",
    "peak_force_N": "peak force (N)", "mean_force_N": "mean force (N)", "force_time_integral_Ns": "force-time (N s)",
    "jerk_rms": "jerk RMS (N/s^3)",
}


def _svg(fig: Figure) -> str:
    out = io.StringIO()
    fig.savefig(out, format="svg", bbox_inches="tight")
    text = out.getvalue()
    return text[text.index("<svg"):]                  # inline in a page: no XML prolog or doctype


def metrics_of(report: dict[str, Any], who: str = "metrics") -> dict[str, float | None]:
    """The metrics a page shows of the trainee (``who="metrics"``) or the expert (``"expert"``): a hand log's
    clinical ones, else the replay's."""
    m = report[who]
    return dict(m["clinical"]) if "clinical" in m else {k: v for k, v in m.items() if k in METRIC_LABELS}


def cohort_svg(sessions: dict[str, list[StoredSession]], marks: dict[str, PassMark]) -> str:
    """Every trainee's score over their sessions, with each scene's pass mark."""
    fig = Figure(figsize=(7.5, 3.2))
    ax = fig.add_subplot()
    for trainee, rows in sessions.items():
        ax.plot(np.arange(1, len(rows) + 1), [r.score for r in rows], marker="o", ms=2.5, lw=1, label=trainee)
    for mark in marks.values():
        ax.axhline(mark.mark, ls="--", color="0.3", lw=1)
        ax.annotate(f"pass mark {mark.mark:.1f}", (1, mark.mark), xytext=(2, 3), textcoords="offset points", fontsize=7)
    ax.set(xlabel="session", ylabel="score", ylim=(0, 102))
    if len(sessions) <= 16:
        ax.legend(fontsize=6, ncols=2, loc="center left", bbox_to_anchor=(1.0, 0.5), frameon=False)
    return _svg(fig)


def trainee_svg(rows: list[StoredSession], mark: PassMark | None) -> str:
    """A trainee's score and each metric over their sessions, the expert's level dashed."""
    names = ["score"] + list(metrics_of(rows[-1].report))
    cols = 4
    fig = Figure(figsize=(10, 2.1 * math.ceil(len(names) / cols)))
    x = np.arange(1, len(rows) + 1)
    for i, name in enumerate(names):
        ax = fig.add_subplot(math.ceil(len(names) / cols), cols, i + 1)
        if name == "score":
            values = [r.score for r in rows]
            expert = rows[-1].report["expert_parts"]["score"]
            if mark is not None:
                ax.axhline(mark.mark, color="#b03030", lw=1, ls=":", label="pass mark")
        else:
            values = [_number(metrics_of(r.report).get(name)) for r in rows]
            expert = _number(metrics_of(rows[-1].report, "expert").get(name))
        ax.plot(x, values, marker="o", ms=3, lw=1.2, color="#1f5f99")
        if expert is not None and math.isfinite(expert):
            ax.axhline(expert, color="0.35", lw=1, ls="--", label="expert")
        ax.set_title(METRIC_LABELS.get(name, name), fontsize=8)
        ax.tick_params(labelsize=7)
        if i == 0:
            ax.legend(fontsize=6, frameon=False)
    fig.supxlabel("session", fontsize=8)
    fig.tight_layout()
    return _svg(fig)


def _number(value: Any) -> float:
    return math.nan if value is None else float(value)


def parts_svg(report: dict[str, Any]) -> str:
    """The score's parts, the trainee's beside the expert's."""
    names = list(report["weights"])
    fig = Figure(figsize=(6, 2.4))
    ax = fig.add_subplot()
    x = np.arange(len(names))
    ax.bar(x - 0.2, [report[k] for k in names], 0.4, label="trainee", color="#1f5f99")
    ax.bar(x + 0.2, [report["expert_parts"][k] for k in names], 0.4, label="expert", color="0.7")
    ax.set_xticks(x, names, fontsize=8)
    ax.set(ylim=(0, 1.05), ylabel="part (0-1)")
    ax.legend(fontsize=7, frameon=False, ncols=2, loc="lower right")
    return _svg(fig)


def replay_gif(log_name: str, data: bytes, scene: dict[str, Any] | None) -> bytes:
    """The replay of a kept log on its scene, as an animated GIF of :data:`FRAMES` frames."""
    with log_file(data, log_name) as path:
        schema, table = read_log(path)
        _, config, _ = scene_of(path, schema, scene)
    steps = (table[-1, 0] - table[0, 0]) / config["dynamics"]["dt"]
    every = max(1, int(round(steps / FRAMES)))
    with _RENDER:
        frames = (replay_hand(table, config, log_name, frame_every=every) if schema is HAND_LOG
                  else replay(table, config, frame_every=every)).frames
    images = [Image.fromarray(f).convert("P", palette=Image.Palette.ADAPTIVE, colors=128) for f in frames]
    out = io.BytesIO()
    images[0].save(out, format="GIF", save_all=True, append_images=images[1:], loop=0,
                   duration=int(1000 * PLAYBACK_S / len(images)))
    return out.getvalue()

