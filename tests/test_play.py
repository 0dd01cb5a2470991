"""softenv play, headless (SDL's dummy video driver) with a scripted player: the recorded device log
scores like the session it came from."""

import numpy as np
import pygame
import pytest

from softenv.training import play
from softenv.training.logs import read_log


def _key(key: int, down: bool) -> "pygame.event.Event":
    return pygame.event.Event(pygame.KEYDOWN if down else pygame.KEYUP, key=key)


def _player(step: int) -> list:
    """Insert, lift with the arrows, sweep right with D, and a mouse drag that lifts harder."""
    return {0: [_key(pygame.K_LEFT, True)], 8: [_key(pygame.K_LEFT, False), _key(pygame.K_DOWN, True)],
            25: [_key(pygame.K_DOWN, False), _key(pygame.K_d, True)], 35: [_key(pygame.K_d, False)],
            40: [pygame.event.Event(pygame.MOUSEBUTTONDOWN, button=1, pos=(100, 100)),
                 pygame.event.Event(pygame.MOUSEMOTION, pos=(100, 130), rel=(0, 30), buttons=(1, 0, 0))],
            46: [pygame.event.Event(pygame.MOUSEBUTTONUP, button=1, pos=(100, 130))]}.get(step, [])


def test_a_scripted_session_writes_a_log_that_scores_like_the_session(tmp_path):
    play.headless()
    session = play.run(seconds=1.2, out_dir=tmp_path, realtime=False, script=_player, echo=lambda s: None)
    logs = list(tmp_path.glob("session_*.csv"))
    assert len(logs) == 1 and (tmp_path / f"{logs[0].stem}_score.md").exists()
    schema, table = read_log(logs[0])
    assert schema.columns[1] == "hand_x_m" and len(table) == 61             # 60 control periods and the start
    assert table[8, 1] < -0.01 and table[24, 2] < table[8, 2]                # inserted, then lifted (pressed)
    assert table[-1, 4] > 0.0                                                # swept right
    # the replay of the log is the session: same shape error and clinical metrics
    metrics = session.report["metrics"]
    assert metrics["final_error_mm"] == pytest.approx(session.live_final_error_mm, rel=1e-5)
    for key in ("peak_tongue_force_N", "tongue_force_time_Ns", "hand_path_m", "glottic_view_pct"):
        assert metrics["clinical"][key] == pytest.approx(session.live_clinical[key], rel=1e-4, abs=1e-9), key
    assert 0.0 < session.report["score"] < 100.0


def test_escape_ends_the_session_early_and_an_empty_session_is_an_error(tmp_path):
    play.headless()
    session = play.run(seconds=5.0, out_dir=tmp_path, realtime=False, echo=lambda s: None,
                       script=lambda step: [_key(pygame.K_ESCAPE, True)] if step == 10 else [])
    assert len(session.log) == 11
    with pytest.raises(ValueError, match="ended before its first control period"):
        play.run(seconds=5.0, out_dir=tmp_path / "none", realtime=False, echo=lambda s: None,
                 script=lambda step: [pygame.event.Event(pygame.QUIT)])
    assert not (tmp_path / "none").exists()
    assert np.isfinite(session.log).all()


def test_play_command_runs_headless_and_prints_the_score(tmp_path, capsys):
    from softenv.cli import main

    assert main(["play", "--headless", "--seconds", "0.3", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "score" in out and "/100" in out and list(tmp_path.glob("session_*_score.json"))


def test_a_session_with_keys_held_together_into_the_walls_replays_as_it_was_played(tmp_path):
    """Two and four keys at once drive the hand at full speed on several axes and into its walls: the log is
    accepted, and its replay gives the session's shape error and clinical metrics exactly."""
    play.headless()
    keys = [pygame.K_LEFT, pygame.K_DOWN, pygame.K_d, pygame.K_e]
    script = {0: [_key(k, True) for k in keys[:2]], 20: [_key(k, True) for k in keys[2:]],
              45: [_key(k, False) for k in keys]}
    session = play.run(seconds=1.2, out_dir=tmp_path, realtime=False, script=lambda step: script.get(step, []),
                       echo=lambda s: None)
    metrics = session.report["metrics"]
    assert metrics["final_error_mm"] == session.live_final_error_mm
    for key in ("peak_tongue_force_N", "tongue_force_time_Ns", "hand_path_m", "glottic_view_pct"):
        assert metrics["clinical"][key] == session.live_clinical[key], key


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
    play.run(seconds=0.1, out_dir=tmp_path, realtime=False, echo=lambda s: None)
    assert opened == [] and not pygame.mixer.get_init()
