"""The skills lab's session store, on SQLite and on a real PostgreSQL server: what it keeps, bad input,
migrations from the previous schema, a killed writer, two stations at once, rescoring, deletion."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from datetime import datetime, timezone
from pathlib import Path

import pytest
import sqlalchemy as sa
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext

from skills_support import BACKENDS, fresh_url
from softenv import __version__
from softenv.cli import main
from softenv.skills import schema
from softenv.skills.store import Store, database_url, head_revision, scene_name, upgrade
from softenv.training import scoring
from softenv.training.logs import HAND_LOG, example_log, save_log
from softenv.training.trainee import degrade, expert_hand_log

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(params=BACKENDS)
def url(request, tmp_path):
    yield from fresh_url(request.param, tmp_path)


def snapshot(store: Store) -> dict:
    """Every row of every table, to show a refused write changed nothing."""
    with store.engine.connect() as conn:
        return {t.name: sorted(map(repr, conn.execute(sa.select(t)).all())) for t in schema.metadata.sorted_tables}


def test_a_kept_session_holds_its_raw_log_score_parts_and_every_clinical_metric(url):
    path = example_log("device_logs/too_forceful")
    when = datetime(2026, 10, 1, 9, 30, tzinfo=timezone.utc)
    with Store(url) as store:
        kept = store.add(path, "T-017", recorded_at=when, source="score")
        again = Store(url)                                       # a second connection sees the same
        [row] = again.sessions("T-017")
        assert row == kept and again.raw_log(kept.id) == (path.name, path.read_bytes())
        again.close()
    fresh = scoring.score_file(path)                             # scored on its own, outside the store
    assert kept.score == pytest.approx(fresh["score"], abs=1e-9)
    assert kept.recorded_at == when and kept.scene == "SoftSphereHaptic-v0" and kept.log_kind == HAND_LOG.name
    assert kept.softenv_version == __version__ and kept.formula_version == scoring.SCORE_VERSION
    assert {k: kept.report[k] for k in fresh["weights"]} == pytest.approx({k: fresh[k] for k in fresh["weights"]})
    assert set(kept.report["metrics"]["clinical"]) == set(fresh["metrics"]["clinical"]) and len(fresh["metrics"]["clinical"]) >= 10
    assert kept.report["advice"] == fresh["advice"] and kept.report["trajectory"] == path.name


def test_bad_input_is_one_line_and_leaves_the_store_as_it_was(url, tmp_path):
    good = example_log("device_logs/expert")
    truncated = tmp_path / "truncated.csv"
    text = example_log("device_logs/hesitant_tremulous").read_text()
    truncated.write_text(text[: len(text) // 2].rsplit(",", 1)[0])           # cut in the middle of a row
    with Store(url) as store:
        store.add(good, "T-001")
        before = snapshot(store)
        cases = [
            (lambda: store.add(good, "T-002"), "already kept: session 1 of trainee T-001"),
            (lambda: store.add(truncated, "T-002"), "fields; the header has 5"),
            (lambda: store.add(example_log("device_logs/levers_on_teeth"), "T-002",
                               scene={"tissue": {"law": "stiffening"}}, scene_named="--law stiffening"),
             "asks for another scene"),
            (lambda: store.add(truncated.read_bytes(), "T-002", log_name="log.txt"), "unknown format '.txt'"),
            (lambda: store.add(example_log("device_logs/wrong_direction"), "Jane Doe"), "not a pseudonymous id"),
            (lambda: store.add(example_log("device_logs/wrong_direction"), "T-002", source="email"), "source='email'"),
        ]
        for call, words in cases:
            with pytest.raises(ValueError) as info:
                call()
            assert words in str(info.value) and "\n" not in str(info.value), str(info.value)
            assert snapshot(store) == before


def test_the_schema_the_store_reads_is_the_one_its_migrations_make(url):
    with Store(url) as store, store.engine.connect() as conn:
        assert compare_metadata(MigrationContext.configure(conn), schema.metadata) == []
        assert MigrationContext.configure(conn).get_current_revision() == head_revision()


def test_a_store_of_the_previous_schema_opens_upgraded_with_nothing_lost(url):
    engine = sa.create_engine(database_url(url))
    upgrade(engine, "0001")                                       # the first schema: no pass marks
    log = example_log("device_logs/expert")
    report = scoring.score_file(log)
    now = datetime(2026, 9, 1, tzinfo=timezone.utc)
    with engine.begin() as conn:
        assert "pass_marks" not in sa.inspect(conn).get_table_names()
        conn.execute(sa.text("INSERT INTO trainees (id, name, created_at) VALUES ('T-9', NULL, :t)"), {"t": now})
        conn.execute(sa.text("INSERT INTO sessions (trainee_id, recorded_at, scene, scene_sections, log_kind, log_name, "
                             "log_bytes, log_sha256, source, softenv_version) VALUES ('T-9', :t, 'SoftSphereHaptic-v0', "
                             "'{}', :kind, 'expert.csv', :data, :sha, 'score', '0.0.9')"),
                     {"t": now, "kind": HAND_LOG.name, "data": log.read_bytes(), "sha": "0" * 64})
        conn.execute(sa.text("INSERT INTO scores (session_id, formula_version, score, report, softenv_version, scored_at) "
                             "VALUES (1, 1, :score, :report, '0.0.9', :t)"),
                     {"score": report["score"], "report": json.dumps(report), "t": now})
    engine.dispose()
    with Store(url) as store:
        [row] = store.sessions()
        assert (row.trainee, row.score, row.softenv_version, row.recorded_at) == ("T-9", report["score"], "0.0.9", now)
        assert store.raw_log(1) == ("expert.csv", log.read_bytes()) and store.pass_marks() == {}
        with store.engine.connect() as conn:
            assert MigrationContext.configure(conn).get_current_revision() == head_revision()


def test_a_store_of_a_newer_softenv_is_refused_by_name(tmp_path):
    path = tmp_path / "lab.sqlite"
    Store(path).close()
    engine = sa.create_engine(f"sqlite:///{path}")
    with engine.begin() as conn:
        conn.execute(sa.text("UPDATE alembic_version SET version_num = '0099'"))
    engine.dispose()
    with pytest.raises(ValueError, match="revision '0099', which this softenv .* does not know.*newer softenv"):
        Store(path)
    (tmp_path / "junk.sqlite").write_bytes(b"this is not a database" * 100)
    with pytest.raises(ValueError, match="cannot be opened as a session store"):
        Store(tmp_path / "junk.sqlite")


WRITER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    import sqlalchemy as sa
    from softenv.skills.store import Store
    url, log, trainee, marker, hold = sys.argv[1:6]
    store = Store(url)
    def commit(conn):                  # inside the transaction, its rows written, before COMMIT
        Path(marker).write_text("writing")
        time.sleep(float(hold))
    sa.event.listen(store.engine, "commit", commit)
    store.add(log, trainee)
    print("landed")
""")


def writer(url: str, log: Path, trainee: str, marker: Path, hold: float) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", WRITER, url, str(log), trainee, str(marker), str(hold)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})


def wait_for(path: Path, process: subprocess.Popen, seconds: float = 120.0) -> None:
    end = time.monotonic() + seconds
    while not path.exists():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < end, "the writer never reached its commit"
        time.sleep(0.05)


def test_a_writer_killed_mid_write_leaves_the_store_as_it_was(url, tmp_path):
    with Store(url) as store:
        store.add(example_log("device_logs/expert"), "T-1")
        before = snapshot(store)
    marker = tmp_path / "marker"
    process = writer(url, example_log("device_logs/too_forceful"), "T-2", marker, 600)
    wait_for(marker, process)
    process.send_signal(signal.SIGKILL)
    process.wait()
    with Store(url) as store:
        assert snapshot(store) == before                          # neither the new trainee nor the session
        store.add(example_log("device_logs/too_forceful"), "T-2")  # and the store takes writes again
        assert [s.trainee for s in store.sessions()] == ["T-1", "T-2"]


def test_two_stations_writing_at_once_both_land(url, tmp_path):
    Store(url).close()
    logs = [example_log("device_logs/levers_on_teeth"), example_log("device_logs/wrong_direction")]
    markers = [tmp_path / "a", tmp_path / "b"]
    # each holds its transaction open for a second at its commit, so the two writes overlap
    processes = [writer(url, log, "T-new", marker, 1.0) for log, marker in zip(logs, markers)]
    outputs = [p.communicate(timeout=300) for p in processes]
    assert [p.returncode for p in processes] == [0, 0], outputs
    with Store(url) as store:
        assert sorted(s.log_name for s in store.sessions("T-new")) == sorted(log.name for log in logs)
        assert [t.id for t in store.trainees()] == ["T-new"]


def test_rescoring_keeps_the_old_scores_beside_the_new(url, monkeypatch):
    with Store(url) as store:
        first = store.add(example_log("device_logs/hesitant_tremulous"), "T-5")
        monkeypatch.setattr(scoring, "SCORE_VERSION", scoring.SCORE_VERSION + 1)
        monkeypatch.setattr(scoring, "HAND_WEIGHTS", {**scoring.HAND_WEIGHTS, "speed": 0.5})
        progress = []
        assert store.rescore(lambda done, total: progress.append((done, total))) == 1 and progress == [(1, 1)]
        assert store.rescore() == 0                                 # every session has a score of the new version now
        now = store.session(first.id)
        old = first.formula_version
        assert now.formula_version == old + 1 and now.score == pytest.approx(
            scoring.score_file(example_log("device_logs/hesitant_tremulous"))["score"])
        history = store.score_history(first.id)
        assert [(v, s) for v, s, _ in history] == [(old, first.score), (old + 1, now.score)] and now.score != first.score


def test_deleting_a_trainee_removes_their_sessions_logs_and_scores_from_the_file(tmp_path):
    log = degrade(expert_hand_log(), tremor=0.3, seed=4)
    path = tmp_path / "private.csv"
    save_log(log, path, HAND_LOG, note="PRIVATE-MARKER-4711")
    db = tmp_path / "lab.sqlite"
    with Store(db) as store:
        store.add(path, "T-gone-42", name="Given Name")
        store.add(example_log("device_logs/expert"), "T-stays")
        assert store.delete_trainee("T-gone-42") == 1
        assert [t.id for t in store.trainees()] == ["T-stays"] and [s.trainee for s in store.sessions()] == ["T-stays"]
        with store.engine.connect() as conn:
            assert conn.execute(sa.text("SELECT count(*) FROM scores")).scalar() == 1
        with pytest.raises(ValueError, match="'T-gone-42' is not in store"):
            store.delete_trainee("T-gone-42")
    data = db.read_bytes()
    for secret in (b"PRIVATE-MARKER-4711", b"T-gone-42", b"Given Name"):
        assert secret not in data, secret


def test_the_export_has_a_row_a_session_with_parts_and_clinical_metrics(tmp_path):
    with Store(tmp_path / "lab.sqlite") as store:
        store.add(example_log("device_logs/expert"), "T-1")
        store.add(example_log("trajectories/too_forceful"), "T-2")
        lines = store.export_csv().splitlines()
    header = lines[0].split(",")
    assert len(lines) == 3 and {"trainee", "score", "part_teeth", "peak_incisor_force_N", "glottic_view_pct",
                                "formula_version", "softenv_version"} <= set(header)
    assert scene_name("force-command log", {}) == "SoftSphere-v0"


def test_a_session_on_an_airway_grade_is_kept_under_that_grade_and_gets_its_own_pass_mark(tmp_path):
    from softenv.envs import airway_scene
    from softenv.skills.passmark import contrasting_groups
    from softenv.training.hand import haptic_config
    from softenv.training.logs import HAND_LOG, save_log
    from softenv.training.trainee import expert_hand_log

    assert scene_name(HAND_LOG.name, airway_scene(3)) == "SoftSphereAirway-v0 grade 3"
    custom = {**airway_scene(3), "airway": {"grade": 3, "mouth_opening": 2.0}}
    assert scene_name(HAND_LOG.name, custom).startswith("SoftSphereHaptic-v0 {")   # other settings: its sections
    path = tmp_path / "graded.csv"
    save_log(expert_hand_log(haptic_config(airway_scene(3))), path, HAND_LOG, scene=airway_scene(3))
    with Store(tmp_path / "lab.sqlite") as store:
        store.add(path, "T-9")
        session = store.sessions("T-9")[0]
        assert session.scene == "SoftSphereAirway-v0 grade 3" and session.report["airway"]["grade"] == 3
        mark = contrasting_groups(session.scene, session.report["scene"], per_group=3)
        normal = contrasting_groups("SoftSphereHaptic-v0", None, per_group=3)
        assert mark.scene == "SoftSphereAirway-v0 grade 3" and mark.mark != normal.mark


def test_score_and_play_keep_their_sessions(url, tmp_path, capsys):
    assert main(["score", "--example", "device_logs/levers_on_teeth", "--trainee", "T-3", "--store", url]) == 0
    assert "kept as session 1 of trainee T-3" in capsys.readouterr().out
    assert main(["play", "--headless", "--seconds", "0.3", "--out", str(tmp_path / "play"), "--trainee", "T-3",
                 "--store", url]) == 0
    assert "kept as session 2 of trainee T-3" in capsys.readouterr().out
    with Store(url) as store:
        rows = store.sessions("T-3")
        assert [s.source for s in rows] == ["score", "play"]
        played = next((tmp_path / "play").glob("session_*.csv"))
        assert store.raw_log(rows[1].id) == (played.name, played.read_bytes())
    assert main(["score", "--example", "device_logs/expert", "--store", url]) == 2
    assert "--store keeps a session for a trainee: give --trainee" in capsys.readouterr().err
