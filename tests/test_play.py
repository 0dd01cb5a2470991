"""softenv play, headless (SDL's dummy video driver) with a scripted player, tested as a person uses it:
what the window shows (the task, the target, gauges that move and turn red past their limits, the teeth
flagged when touched, the end screen's score and advice), the controls (ramped keys, Shift, mouse,
gamepad, pause), and the recorded device log, which scores like the session it came from."""

import numpy as np
import pygame
import pytest

from softenv.training import play
from softenv.training.inputs import CONTROLS, DEAD_ZONE, FINE, RAMP_FLOOR, RAMP_S, PygameInput
from softenv.training.logs import SENSOR_COLUMNS, read_log, read_readings
from softenv.training.scoring import score_file
from softenv.training.play_view import DANGER, HAND, INK, PANEL, SCALE_BAR_MM, SOLID, TARGET, TOOTH

DT = 0.02
MAX_HAND_SPEED = 0.2          # SoftSphereHaptic-v0's device: m/s at full action


def _key(key: int, down: bool) -> "pygame.event.Event":
    return pygame.event.Event(pygame.KEYDOWN if down else pygame.KEYUP, key=key)


def _player(step: int) -> list:
    """Insert, lift with the arrows, sweep right with D, and a mouse drag that lifts harder."""
    return {0: [_key(pygame.K_LEFT, True)], 8: [_key(pygame.K_LEFT, False), _key(pygame.K_DOWN, True)],
            25: [_key(pygame.K_DOWN, False), _key(pygame.K_d, True)], 35: [_key(pygame.K_d, False)],
            40: [pygame.event.Event(pygame.MOUSEBUTTONDOWN, button=1, pos=(100, 100)),
                 pygame.event.Event(pygame.MOUSEMOTION, pos=(100, 130), rel=(0, 30), buttons=(1, 0, 0))],
            46: [pygame.event.Event(pygame.MOUSEBUTTONUP, button=1, pos=(100, 130))]}.get(step, [])


def _ramp_distance(periods: int) -> float:
    """How far a key held for ``periods`` control periods moves the hand, by the documented ramp."""
    held = DT * np.arange(1, periods + 1)
    return float(MAX_HAND_SPEED * DT * np.sum(RAMP_FLOOR + (1 - RAMP_FLOOR) * np.minimum(held / RAMP_S, 1.0)))


def test_a_scripted_session_writes_a_log_that_scores_like_the_session(tmp_path):
    play.headless()
    session = play.run(seconds=1.2, out_dir=tmp_path, realtime=False, script=_player, echo=lambda s: None,
                       screens=False)
    logs = list(tmp_path.glob("session_*.csv"))
    assert len(logs) == 1 and (tmp_path / f"{logs[0].stem}_score.md").exists()
    schema, table = read_log(logs[0])
    assert schema.columns[1] == "hand_x_m" and len(table) == 61             # 60 control periods and the start
    # the insert key held for 8 periods ramps up as documented (the blade starts level: insert is -x)
    assert table[8, 1] == pytest.approx(-_ramp_distance(8), rel=1e-9)
    assert table[24, 2] < table[8, 2]                                        # then lifted (pressed)
    assert table[-1, 4] > 0.0                                                # swept right
    # the device's sensors, a reading a row: the tongue's force (its peak the report's) and the blade's height
    readings = read_readings(logs[0])
    assert sorted(readings) == sorted(SENSOR_COLUMNS) and readings["tongue_force_N"][0] == 0.0
    # the replay of the log is the session: same shape error and clinical metrics
    metrics = session.report["metrics"]
    assert readings["tongue_force_N"].max() == pytest.approx(metrics["clinical"]["peak_tongue_force_N"], rel=1e-4)
    assert np.ptp(readings["blade_z_mm"]) > 1.0                               # lifted by millimetres
    assert metrics["final_error_mm"] == pytest.approx(session.live_final_error_mm, rel=1e-5)
    for key in ("peak_tongue_force_N", "tongue_force_time_Ns", "hand_path_m", "glottic_view_pct"):
        assert metrics["clinical"][key] == pytest.approx(session.live_clinical[key], rel=1e-4, abs=1e-9), key
    assert 0.0 < session.report["score"] < 100.0


def test_a_session_makes_its_scene_once_and_reports_what_scoring_its_log_reports(tmp_path, scene_makes):
    """The session's scene is made once, at its start, and the env and the scoring take it; the report equals
    ``softenv score`` of the written log, which makes the scene again from the file."""
    play.headless()
    made = scene_makes
    session = play.run(seconds=0.6, out_dir=tmp_path, realtime=False, script=_player, echo=lambda s: None,
                       screens=False, scene={"reward": {"safe_force": 7.0}})
    assert len(made) == 2                                   # scene_config: SoftSphereHaptic-v0's scene, then the sections
    again = score_file(session.log_path)
    assert again["score"] == session.report["score"] and again["scene"] == session.report["scene"]
    assert again["safe_force_N"] == 7.0 and again["metrics"] == session.report["metrics"]


def test_escape_ends_the_session_early_and_an_empty_session_is_an_error(tmp_path):
    play.headless()
    session = play.run(seconds=5.0, out_dir=tmp_path, realtime=False, echo=lambda s: None, screens=False,
                       script=lambda step: [_key(pygame.K_ESCAPE, True)] if step == 10 else [])
    assert len(session.log) == 11
    with pytest.raises(ValueError, match="ended before its first control period"):
        play.run(seconds=5.0, out_dir=tmp_path / "none", realtime=False, echo=lambda s: None, screens=False,
                 script=lambda step: [pygame.event.Event(pygame.QUIT)])
    assert not (tmp_path / "none").exists()
    assert np.isfinite(session.log).all()


def test_play_command_runs_headless_and_prints_the_score(tmp_path, capsys):
    from softenv.cli import main

    assert main(["play", "--headless", "--seconds", "0.3", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "score" in out and "/100" in out and list(tmp_path.glob("session_*_score.json"))


def test_a_session_with_keys_held_together_into_the_walls_replays_as_it_was_played(tmp_path):
    """Two and four keys at once drive the hand on several axes and into its walls (the keys still ramping
    when it reaches them): the log is accepted, and its replay gives the session's shape error and clinical
    metrics to rounding, because the keys steer to the pose they reach as the replay does (hand.pose_after)."""
    play.headless()
    keys = [pygame.K_LEFT, pygame.K_DOWN, pygame.K_d, pygame.K_e]
    script = {0: [_key(k, True) for k in keys[:2]], 20: [_key(k, True) for k in keys[2:]],
              45: [_key(k, False) for k in keys]}
    session = play.run(seconds=1.2, out_dir=tmp_path, realtime=False, script=lambda step: script.get(step, []),
                       echo=lambda s: None, screens=False)
    metrics = session.report["metrics"]
    assert metrics["final_error_mm"] == pytest.approx(session.live_final_error_mm, rel=1e-9)
    for key in ("peak_tongue_force_N", "tongue_force_time_Ns", "hand_path_m", "glottic_view_pct"):
        assert metrics["clinical"][key] == pytest.approx(session.live_clinical[key], rel=1e-9, abs=1e-12), key


def test_without_a_display_play_refuses_in_one_line_unless_headless(tmp_path, monkeypatch, capsys):
    from softenv.cli import main

    for var in ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(play.sys, "platform", "linux")
    assert main(["play", "--seconds", "0.3", "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no display" in err and "--headless" in err
    assert not (tmp_path / "s").exists()
    monkeypatch.setenv("DISPLAY", ":99")
    assert play.display_available()


def test_a_session_opens_no_sound_device(tmp_path, monkeypatch):
    """pygame.init() would open the mixer (a page of ALSA errors on machines without sound): play does not."""
    play.headless()
    opened = []
    monkeypatch.setattr(pygame, "init", lambda: opened.append("init"))
    monkeypatch.setattr(pygame.mixer, "init", lambda *a, **k: opened.append("mixer"))
    play.run(seconds=0.1, out_dir=tmp_path, realtime=False, echo=lambda s: None, screens=False)
    assert opened == [] and not pygame.mixer.get_init()


# -- what a person sees --------------------------------------------------------------------------------

class Recorder:
    """``on_frame``: every frame's phase, what was drawn, and copies of chosen frames."""

    def __init__(self, keep=()):
        self.phases, self.drawn, self.frames, self.keep = [], [], {}, set(keep)

    def __call__(self, frame, phase, view):
        self.phases.append(phase)
        self.drawn.append(dict(view.drawn))
        if frame in self.keep or (phase == "end" and "end" not in self.frames):
            self.frames["end" if phase == "end" else frame] = pygame.surfarray.array3d(view.screen).copy()


def _pixels(image, rect):
    x, y, w, h = rect
    return image[x:x + w, y:y + h].reshape(-1, 3)


def _has_colour(image, rect, colour, tol=0):
    return bool((np.abs(_pixels(image, rect).astype(int) - colour) <= tol).all(axis=1).any())


def test_the_start_screen_states_the_task_and_waits_for_the_player(tmp_path):
    play.headless()
    seen = Recorder()
    script = {6: [_key(pygame.K_SPACE, True)], 40: [_key(pygame.K_RETURN, True)]}
    session = play.run(seconds=0.4, out_dir=tmp_path, realtime=False, echo=lambda s: None, on_frame=seen,
                       script=lambda f: script.get(f, []))
    assert seen.phases[:6] == ["start"] * 6 and "start" not in seen.phases[6:]
    assert {"title", "task", "start", "target outline"} <= set(seen.drawn[0])
    assert seen.phases.count("run") == 20 and len(session.log) == 21       # waiting on the start screen is not played
    # the end screen holds until Enter (or Esc, or closing the window): frames 0-5 start, 6 starts the session,
    # 7-26 play it, 27-40 show the end screen
    assert seen.phases[26:] == ["end"] * 14 and len(seen.phases) == 40


def test_a_session_shows_the_target_gauges_that_move_and_the_score_at_the_end(tmp_path):
    play.headless()
    seen = Recorder(keep=(1, 30))
    script = {0: [_key(pygame.K_LEFT, True)], 12: [_key(pygame.K_LEFT, False), _key(pygame.K_DOWN, True)],
              30: [_key(pygame.K_DOWN, False)], 1: []}
    session = play.run(seconds=1.0, out_dir=tmp_path, realtime=False, echo=lambda s: None, on_frame=seen,
                       screens=True, script=lambda f: ([_key(pygame.K_SPACE, True)] if f == 0 else [])
                       + script.get(f - 1, []) + ([_key(pygame.K_ESCAPE, True)] if f == 60 else []))
    first, pressed, end = seen.frames[1], seen.frames[30], seen.frames["end"]
    drawn = seen.drawn[30]
    # the target: its dashed outline in the side view, in the target's green
    assert _has_colour(pressed, drawn["target outline"], TARGET)
    # the gauges move: the tongue-force bar is empty at the start and filled when pressing
    assert seen.drawn[1]["gauge:tongue"][2] == 0 < drawn["gauge:tongue"][2]
    assert "gauge:tongue limit" in drawn and "gauge:incisors limit" in drawn
    # the remaining error as colour: the 3D tongue is redder at rest than when pressed toward the target
    red = lambda image: float(np.mean(_pixels(image, SOLID)[:, 0].astype(int) - _pixels(image, SOLID)[:, 1]))  # noqa: E731
    assert red(first) > red(pressed)
    # the end screen: the score, each part, two pieces of advice, drawn on the card
    last = seen.drawn[-1]
    assert {"score", "leave", "advice:0"} <= set(last) and all(f"part:{k}" in last for k in session.report["weights"])
    assert _pixels(end, last["score"]).min() < 60                          # dark text on the white card
    assert len(session.report["advice"]) == 2 and session.report["score"] < 100


def test_the_tongue_gauge_turns_red_past_the_safe_force_and_the_teeth_are_flagged_when_touched(tmp_path):
    """A low safe force (5 N) is passed while pressing; levering back on the teeth (ease off and tip the blade
    up, as scripts/laryngoscope_frames.py does) loads the incisors: the side view says so where it happens."""
    play.headless()
    seen = Recorder()
    script = {0: [_key(pygame.K_LEFT, True)], 10: [_key(pygame.K_LEFT, False), _key(pygame.K_DOWN, True)],
              22: [_key(pygame.K_DOWN, False), _key(pygame.K_UP, True), _key(pygame.K_q, True)]}
    play.run(seconds=1.2, out_dir=tmp_path, realtime=False, echo=lambda s: None, screens=False, on_frame=seen,
             scene={"reward": {"safe_force": 5.0}}, script=lambda f: script.get(f, []))
    touched = [d for d in seen.drawn if "incisor contact" in d]
    assert touched, "the incisors were never flagged"
    assert not any("incisor contact" in d for d in seen.drawn[:10])        # not before the blade reaches them


def test_the_side_view_draws_lower_incisors_where_the_airway_has_them(tmp_path):
    """An airway with an interincisal gap shows the lower incisors under the blade, in the teeth's colour; one
    without shows none."""
    play.headless()
    for scene, lower in (({"airway": {"interincisal_gap": 30.0}}, True), ({}, False)):
        seen = Recorder(keep=(3,))
        play.run(seconds=0.1, out_dir=tmp_path / str(lower), realtime=False, echo=lambda s: None, screens=False,
                 on_frame=seen, scene=scene)
        assert ("lower incisors" in seen.drawn[3]) == lower
        if lower:
            assert _has_colour(seen.frames[3], seen.drawn[3]["lower incisors"], TOOTH)


def _only_text(image, rect, colour, tol=6.0):
    """Whether every pixel of ``rect`` is the label's colour blended with the white panel: nothing drawn under it."""
    p = _pixels(image, rect).astype(float)
    ink, paper = np.array(colour, dtype=float), np.array(PANEL, dtype=float)
    t = np.clip((p - ink) @ (paper - ink) / np.dot(paper - ink, paper - ink), 0.0, 1.0)
    return bool(np.linalg.norm(p - (ink + t[:, None] * (paper - ink)), axis=1).max() <= tol)


def test_the_side_view_labels_sit_on_blank_panel_and_its_scale_bar_is_to_scale(tmp_path):
    """Inserting, pressing and levering onto the teeth: in every kept frame each label of the side view
    (but the tongue's, written on it) covers nothing drawn, the teeth's warning included; the scale bar
    is as long in pixels per mm as the tongue at rest (30 mm radius) is wide."""
    play.headless()
    seen = Recorder(keep=(1, 12, 20, 30, 45, 60))
    script = {0: [_key(pygame.K_LEFT, True)], 10: [_key(pygame.K_LEFT, False), _key(pygame.K_DOWN, True)],
              22: [_key(pygame.K_DOWN, False), _key(pygame.K_UP, True), _key(pygame.K_q, True)]}
    play.run(seconds=1.2, out_dir=tmp_path, realtime=False, echo=lambda s: None, screens=False, on_frame=seen,
             script=lambda f: script.get(f, []))
    checked = set()
    for frame, image in seen.frames.items():
        if frame == "end" or seen.phases[frame] != "run":           # the cards over the start and end dim it
            continue
        drawn = seen.drawn[frame]
        labels = {n: r for n, r in drawn.items() if (n.startswith("label:") and n != "label:tongue")
                  or n in ("glottic view", "incisor contact")}
        for name, rect in labels.items():
            colour = HAND if name == "label:hand" else DANGER if name == "incisor contact" else INK
            assert _only_text(image, rect, colour), f"frame {frame}: the label {name!r} covers a drawing"
            checked.add(name)
    assert {"label:hand", "label:handle", "label:blade", "label:eye", "glottic view", "incisor contact"} <= checked
    at_rest = seen.drawn[seen.phases.index("run")]
    px_per_mm = at_rest["tongue"][2] / 60.0
    mm = next(n for n in SCALE_BAR_MM if n * px_per_mm >= 60)
    assert at_rest["scale bar"][2] == pytest.approx(mm * px_per_mm, abs=2)


def test_the_tongue_bar_turns_to_the_danger_colour_past_the_safe_force_only(tmp_path):
    """The same press under the default safe force (30 N) and under 5 N: the bar's colour says which."""
    play.headless()
    script = {0: [_key(pygame.K_LEFT, True)], 10: [_key(pygame.K_LEFT, False), _key(pygame.K_DOWN, True)],
              18: [_key(pygame.K_DOWN, False)]}
    colours = {}
    for safe in (30.0, 5.0):
        last = {}

        def keep(frame, phase, view):
            last["image"], last["drawn"] = pygame.surfarray.array3d(view.screen).copy(), dict(view.drawn)
            last["force"] = view.last_forces["tongue"]

        play.run(seconds=0.5, out_dir=tmp_path / str(safe), realtime=False, echo=lambda s: None, screens=False,
                 on_frame=keep, scene={"reward": {"safe_force": safe}}, script=lambda f: script.get(f, []))
        assert 5.0 < last["force"] < 30.0                                     # between the two limits
        x, y, w, h = last["drawn"]["gauge:tongue"]
        colours[safe] = tuple(last["image"][x + 2, y + h // 2])
    assert colours[5.0] == DANGER and colours[30.0] != DANGER


def test_pause_stops_the_clock_and_the_log(tmp_path):
    play.headless()
    seen = Recorder()
    script = {3: [_key(pygame.K_SPACE, True)], 13: [_key(pygame.K_p, True)]}
    session = play.run(seconds=0.2, out_dir=tmp_path, realtime=False, echo=lambda s: None, screens=False, on_frame=seen,
                       script=lambda f: script.get(f, []))
    assert seen.phases == ["run"] * 3 + ["paused"] * 10 + ["run"] * 7
    assert "paused" in seen.drawn[5] and len(session.log) == 11


# -- the controls ----------------------------------------------------------------------------------------

class _Pad:
    def __init__(self, axes):
        self.axes = axes

    def get_numaxes(self):
        return len(self.axes)

    def get_axis(self, j):
        return self.axes[j]


def test_keys_ramp_and_shift_slows_them_and_mouse_and_gamepad_add():
    pygame.display.init()
    try:
        device = PygameInput(pygame)
        device.handle(_key(pygame.K_LEFT, True))
        rates = [device.rates(DT)[0] for _ in range(40)]
        expected = RAMP_FLOOR + (1 - RAMP_FLOOR) * np.minimum(DT * np.arange(1, 41) / RAMP_S, 1.0)
        assert np.allclose(rates, expected, atol=1e-6) and rates[-1] == 1.0
        device.handle(_key(pygame.K_LEFT, False))
        assert device.rates(DT)[0] == 0.0                             # released: stops, and the ramp restarts
        device.handle(_key(pygame.K_LSHIFT, True))
        device.handle(_key(pygame.K_d, True))
        assert device.rates(DT)[2] == pytest.approx(FINE * (RAMP_FLOOR + (1 - RAMP_FLOOR) * DT / RAMP_S))
        device.handle(_key(pygame.K_d, False))
        device.handle(_key(pygame.K_LSHIFT, False))
        device.handle(pygame.event.Event(pygame.MOUSEBUTTONDOWN, button=1, pos=(100, 100)))
        device.handle(pygame.event.Event(pygame.MOUSEMOTION, pos=(70, 130), rel=(-30, 30), buttons=(1, 0, 0)))
        assert np.allclose(device.rates(DT), [0.5, 0.5, 0.0, 0.0])   # half of 60 px: half speed, two axes
        device.handle(pygame.event.Event(pygame.MOUSEBUTTONUP, button=1, pos=(70, 130)))
        device.pads = [_Pad([DEAD_ZONE / 2, -1.0, 0.5, 0.0])]                # drift inside the dead zone is ignored
        a = device.rates(DT)
        assert a[0] == 0.0 and a[1] == -1.0 and a[2] == pytest.approx((0.5 - DEAD_ZONE) / (1 - DEAD_ZONE))
    finally:
        pygame.quit()


def test_play_help_lists_every_control(capsys):
    from softenv.cli import main

    assert main(["play", "--help"]) == 0
    out = capsys.readouterr().out
    assert all(key in out and what in out for key, what in CONTROLS)
