"""The session store: every scored session a skills lab keeps, in any database SQLAlchemy reaches.

``Store("skills.sqlite")`` opens (or makes) SQLite in a file, the embedded default: nothing to set up.
``Store("postgresql+psycopg://user:password@host/db")`` opens PostgreSQL, for a program whose stations
write to one server. Opening migrates the schema to this softenv's newest (:mod:`.migrations`,
Alembic), so a store made by an older softenv opens, upgraded, with nothing lost; a store made by a
newer one is refused by name.

A session is added in one transaction after its log has been checked and scored (:func:`add`): a
writer killed at any point leaves the store as it was, and two stations adding at once both land
(SQLite waits up to :data:`BUSY_TIMEOUT_S` for the other's write; PostgreSQL serialises them).
Bad input is one ``ValueError`` line and no write: a log that fails its checks (a truncated file, a
row out of range), a log of another scene than the one asked for, a log already kept (by its
SHA-256), a trainee id that is not a pseudonym's form.

Scores carry the formula version they were made with (:data:`softenv.training.scoring.SCORE_VERSION`):
:meth:`Store.rescore` scores every stored raw log again under the current formula and keeps the old
scores beside the new ones.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import json
import math
import re
import tempfile
from dataclasses import dataclass
from datetime import datetime, timezone
from importlib.resources import files
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import sqlalchemy as sa
from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.engine import Connection, Engine

from .. import __version__
from ..airway import GRADES
from ..envs import airway_scene
from ..training import scoring
from ..training.logs import HAND_LOG, MAX_FILE_BYTES
from . import schema
from .passmark import PassMark

DEFAULT_STORE = "skills.sqlite"
BUSY_TIMEOUT_S = 30.0                   # how long a SQLite writer waits for another station's write
TRAINEE_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")
SOURCES = ("play", "score", "upload", "api", "demo")
TREND_SESSIONS = 5                      # a trainee's trend: the slope of the score over their last 5 sessions
MIGRATIONS = Path(str(files(__package__ or "softenv.skills") / "migrations"))


def database_url(store: str | Path) -> str:
    """A database URL from ``store``: a URL as is (``postgresql+psycopg://...``), else a file path for SQLite."""
    text = str(store)
    if "://" in text:
        return text
    return f"sqlite:///{Path(text).expanduser().resolve()}"


def scene_name(log_kind: str, sections: dict[str, Any]) -> str:
    """How the store names a scene: the log's id (SoftSphereHaptic-v0 for hand poses, SoftSphere-v0 for
    force commands), then its sections as compact JSON when it has any; a hand-pose log on an airway grade
    as the grade (``SoftSphereAirway-v0 grade 3``)."""
    base = "SoftSphereHaptic-v0" if log_kind == HAND_LOG.name else "SoftSphere-v0"
    graded = [g for g in GRADES if sections == airway_scene(g)] if log_kind == HAND_LOG.name else []
    if graded:
        return f"SoftSphereAirway-v0 grade {graded[0]}"
    return base if not sections else f"{base} {json.dumps(sections, sort_keys=True, separators=(',', ':'))}"


def check_trainee(trainee: Any) -> str:
    """A trainee's pseudonymous id: 1-64 letters, digits, ``_``, ``.`` or ``-``, starting with a letter or digit."""
    if not isinstance(trainee, str) or not TRAINEE_ID.fullmatch(trainee):
        raise ValueError(f"trainee={trainee!r} is not a pseudonymous id: use 1-64 letters, digits, '_', '.' or '-', "
                         "starting with a letter or digit (for example T-017)")
    return trainee


@dataclass(frozen=True)
class StoredSession:
    """One kept session with its newest score (``report``: :func:`softenv.training.scoring.score_file`'s)."""

    id: int
    trainee: str
    recorded_at: datetime
    scene: str
    log_kind: str
    log_name: str
    source: str
    softenv_version: str
    score: float
    formula_version: int
    report: dict[str, Any]


@dataclass(frozen=True)
class TraineeSummary:
    """A trainee's standing: sessions, latest and best score, the trend (points a session over the last
    :data:`TREND_SESSIONS`, None under two), and the status against the pass mark of their latest scene."""

    id: str
    name: str | None
    sessions: int
    latest: float | None
    best: float | None
    trend: float | None
    last_scene: str | None
    status: str                         # "pass", "not yet", "no mark" or "no sessions"


def _utc(moment: datetime) -> datetime:
    """Stored times are UTC; SQLite hands them back without a zone."""
    return moment.replace(tzinfo=timezone.utc) if moment.tzinfo is None else moment.astimezone(timezone.utc)


def _json_safe(value: Any) -> Any:
    """``value`` with non-finite numbers as None and numpy scalars as Python's (PostgreSQL's JSON has no NaN)."""
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def _on_connect(dbapi_connection: Any, _record: Any) -> None:
    """SQLite per connection: enforce foreign keys, wait for other writers, overwrite deleted data."""
    cursor = dbapi_connection.cursor()
    for pragma in ("foreign_keys=ON", f"busy_timeout={int(BUSY_TIMEOUT_S * 1000)}", "secure_delete=ON"):
        cursor.execute(f"PRAGMA {pragma}")
    cursor.close()


def alembic_config(connection: Connection) -> Config:
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    config.attributes["connection"] = connection
    return config


def head_revision() -> str:
    """The newest schema revision this softenv knows."""
    head = ScriptDirectory.from_config(alembic_config(None)).get_current_head()  # type: ignore[arg-type]
    assert head is not None
    return head


def upgrade(engine: Engine, revision: str = "head") -> None:
    """Migrate the store to ``revision`` (newest by default); a store of an unknown (newer) revision is
    refused. On PostgreSQL an advisory lock keeps two stations from migrating at once."""
    with engine.begin() as connection:
        if engine.dialect.name == "postgresql":
            connection.execute(sa.text("SELECT pg_advisory_xact_lock(7305917)"))
        current = MigrationContext.configure(connection).get_current_revision()
        known = {s.revision for s in ScriptDirectory.from_config(alembic_config(connection)).walk_revisions()}
        if current is not None and current not in known:
            raise ValueError(f"store {engine.url.render_as_string(hide_password=True)} has schema revision {current!r}, "
                             f"which this softenv ({__version__}) does not know (it knows {sorted(known)}): "
                             "it was made by a newer softenv; upgrade softenv to open it")
        if current != (head_revision() if revision == "head" else revision):
            command.upgrade(alembic_config(connection), revision)


class Store:
    """A session store at ``store`` (a file path for SQLite, or a database URL), migrated on opening."""

    def __init__(self, store: str | Path = DEFAULT_STORE) -> None:
        url = database_url(store)
        try:
            self.engine = sa.create_engine(url, pool_pre_ping=True)
        except (sa.exc.ArgumentError, ImportError) as exc:
            raise ValueError(f"store={str(store)!r} is not a database URL or file SQLAlchemy can open: {exc}") from None
        if self.engine.dialect.name == "sqlite":
            sa.event.listen(self.engine, "connect", _on_connect)
        try:
            upgrade(self.engine)
        except (sa.exc.OperationalError, sa.exc.DatabaseError) as exc:
            self.engine.dispose()
            raise ValueError(f"store {self.url} cannot be opened as a session store: {exc.orig or exc}") from None

    @property
    def url(self) -> str:
        """The store's URL with any password hidden."""
        return self.engine.url.render_as_string(hide_password=True)

    def close(self) -> None:
        self.engine.dispose()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- writing -------------------------------------------------------------------------------------

    def add(self, log: str | Path | bytes, trainee: str, *, log_name: str | None = None,
            recorded_at: datetime | None = None, scene: dict[str, Any] | None = None, scene_named: str | None = None,
            source: str = "api", name: str | None = None) -> StoredSession:
        """Check, score and keep one session: ``log`` a file, or its bytes with ``log_name`` (its suffix
        tells CSV from NPZ). ``scene``: the scene the lab expects (a log recording another is refused,
        named ``scene_named``); ``recorded_at``: when it was played (default: the file's modification time,
        or now for bytes); ``name``: the trainee's name, only if the lab chooses to keep one."""
        check_trainee(trainee)
        if source not in SOURCES:
            raise ValueError(f"source={source!r} is not one of {list(SOURCES)}")
        if isinstance(log, (str, Path)):
            path = Path(log)
            if not path.is_file():
                raise ValueError(f"log {str(path)!r} is not a file")
            if path.stat().st_size > MAX_FILE_BYTES:
                raise ValueError(f"log {str(path)!r} has {path.stat().st_size:,} bytes; at most {MAX_FILE_BYTES:,}")
            data, log_name = path.read_bytes(), log_name or path.name
            recorded_at = recorded_at or datetime.fromtimestamp(path.stat().st_mtime, timezone.utc)
        else:
            if log_name is None:
                raise ValueError("log_name is needed with a log's bytes (its suffix, .csv or .npz, names the format)")
            data = bytes(log)
        recorded_at = _utc(recorded_at or datetime.now(timezone.utc))
        digest = hashlib.sha256(data).hexdigest()
        self._refuse_duplicate(digest, log_name)
        report = score_bytes(data, log_name, scene, scene_named)
        key = scene_name(report["log"], report["scene"])
        now = datetime.now(timezone.utc)
        with self.engine.begin() as conn:
            self._ensure_trainee(conn, trainee, name, now)
            try:
                inserted = conn.execute(schema.sessions.insert().values(
                    trainee_id=trainee, recorded_at=recorded_at, scene=key, scene_sections=report["scene"],
                    log_kind=report["log"], log_name=log_name, log_bytes=data, log_sha256=digest, source=source,
                    softenv_version=__version__)).inserted_primary_key
                assert inserted is not None
                session_id = int(inserted[0])
            except sa.exc.IntegrityError:          # another station kept the same log a moment ago
                conn.rollback()
                self._refuse_duplicate(digest, log_name)
                raise
            self._insert_score(conn, session_id, report, now)
        return self.session(session_id)

    def _refuse_duplicate(self, digest: str, log_name: str) -> None:
        with self.engine.connect() as conn:
            row = conn.execute(sa.select(schema.sessions.c.id, schema.sessions.c.trainee_id)
                               .where(schema.sessions.c.log_sha256 == digest)).first()
        if row is not None:
            raise ValueError(f"log {log_name!r} is already kept: session {row.id} of trainee {row.trainee_id} has the "
                             "same bytes (SHA-256); a session is kept once")

    def _ensure_trainee(self, conn: Connection, trainee: str, name: str | None, now: datetime) -> None:
        """Insert the trainee unless present (two stations may add the same new trainee at once)."""
        dialect = {"sqlite": sqlite, "postgresql": postgresql}.get(self.engine.dialect.name)
        values = {"id": trainee, "name": name, "created_at": now}
        if dialect is not None:
            conn.execute(dialect.insert(schema.trainees).values(**values).on_conflict_do_nothing())
        elif conn.execute(sa.select(schema.trainees.c.id).where(schema.trainees.c.id == trainee)).first() is None:
            conn.execute(schema.trainees.insert().values(**values))
        if name is not None:
            conn.execute(schema.trainees.update().where(schema.trainees.c.id == trainee).values(name=name))

    def _insert_score(self, conn: Connection, session_id: int, report: dict[str, Any], now: datetime) -> None:
        conn.execute(schema.scores.insert().values(
            session_id=session_id, formula_version=int(report["formula_version"]), score=float(report["score"]),
            report=_json_safe(report), softenv_version=__version__, scored_at=now))

    def rescore(self, progress: Callable[[int, int], None] | None = None) -> int:
        """Score every session without a score of the current formula version from its raw log, keeping
        the older scores beside the new; returns how many were scored. ``progress(done, total)`` after each."""
        version = scoring.SCORE_VERSION
        with self.engine.connect() as conn:
            scored = sa.select(schema.scores.c.session_id).where(schema.scores.c.formula_version == version)
            todo = conn.execute(sa.select(schema.sessions.c.id, schema.sessions.c.log_bytes, schema.sessions.c.log_name,
                                          schema.sessions.c.scene_sections)
                                .where(schema.sessions.c.id.not_in(scored)).order_by(schema.sessions.c.id)).all()
        for i, row in enumerate(todo):
            report = score_bytes(row.log_bytes, row.log_name, row.scene_sections or None)
            with self.engine.begin() as conn:        # one session a transaction: an interrupted rescore resumes
                if conn.execute(sa.select(schema.scores.c.id).where(
                        (schema.scores.c.session_id == row.id) & (schema.scores.c.formula_version == version))).first() is None:
                    self._insert_score(conn, row.id, report, datetime.now(timezone.utc))
            if progress is not None:
                progress(i + 1, len(todo))
        return len(todo)

    def delete_trainee(self, trainee: str) -> int:
        """Remove a trainee and every session, raw log and score of theirs; returns how many sessions went.
        On SQLite the freed pages are overwritten (``secure_delete``), so the data is gone from the file."""
        check_trainee(trainee)
        with self.engine.begin() as conn:
            if conn.execute(sa.select(schema.trainees.c.id).where(schema.trainees.c.id == trainee)).first() is None:
                raise ValueError(f"trainee {trainee!r} is not in store {self.url}")
            ids = sa.select(schema.sessions.c.id).where(schema.sessions.c.trainee_id == trainee)
            conn.execute(schema.scores.delete().where(schema.scores.c.session_id.in_(ids)))
            gone = conn.execute(schema.sessions.delete().where(schema.sessions.c.trainee_id == trainee)).rowcount
            conn.execute(schema.trainees.delete().where(schema.trainees.c.id == trainee))
        return int(gone)

    def set_pass_mark(self, mark: PassMark) -> None:
        """Keep ``mark`` as its scene's pass mark (replacing the scene's previous one)."""
        with self.engine.begin() as conn:
            conn.execute(schema.pass_marks.delete().where(schema.pass_marks.c.scene == mark.scene))
            conn.execute(schema.pass_marks.insert().values(
                scene=mark.scene, mark=mark.mark, method=mark.method, formula_version=mark.formula_version,
                evidence=_json_safe(mark.evidence()), set_at=datetime.now(timezone.utc)))

    # -- reading -------------------------------------------------------------------------------------

    def _newest_scores(self) -> sa.Subquery:
        s = schema.scores
        newest = sa.select(s.c.session_id, sa.func.max(s.c.formula_version).label("v")).group_by(s.c.session_id).subquery()
        return (sa.select(s).join(newest, (s.c.session_id == newest.c.session_id) & (s.c.formula_version == newest.c.v))
                .subquery())

    def _stored(self, where: Any = None) -> list[StoredSession]:
        """Kept sessions matching ``where`` (all by default), oldest first, each with its newest score."""
        s, sc = schema.sessions, self._newest_scores()
        query = (sa.select(s.c.id, s.c.trainee_id, s.c.recorded_at, s.c.scene, s.c.log_kind, s.c.log_name, s.c.source,
                           s.c.softenv_version, sc.c.score, sc.c.formula_version, sc.c.report)
                 .join(sc, sc.c.session_id == s.c.id).order_by(s.c.recorded_at, s.c.id))
        with self.engine.connect() as conn:
            rows = conn.execute(query if where is None else query.where(where)).all()
        return [StoredSession(r.id, r.trainee_id, _utc(r.recorded_at), r.scene, r.log_kind, r.log_name, r.source,
                              r.softenv_version, r.score, r.formula_version, r.report) for r in rows]

    def sessions(self, trainee: str | None = None) -> list[StoredSession]:
        """Kept sessions (one trainee's, or all), oldest first, each with its newest score."""
        return self._stored(None if trainee is None else schema.sessions.c.trainee_id == trainee)

    def session(self, session_id: int) -> StoredSession:
        found = self._stored(schema.sessions.c.id == session_id)
        if not found:
            raise ValueError(f"session {session_id!r} is not in store {self.url}")
        return found[0]

    def raw_log(self, session_id: int) -> tuple[str, bytes]:
        """A session's log as it was recorded: its name and bytes."""
        with self.engine.connect() as conn:
            row = conn.execute(sa.select(schema.sessions.c.log_name, schema.sessions.c.log_bytes)
                               .where(schema.sessions.c.id == session_id)).first()
        if row is None:
            raise ValueError(f"session {session_id!r} is not in store {self.url}")
        return row.log_name, bytes(row.log_bytes)

    def score_history(self, session_id: int) -> list[tuple[int, float, datetime]]:
        """Every score a session has had: (formula version, score, when scored), oldest version first."""
        s = schema.scores
        with self.engine.connect() as conn:
            rows = conn.execute(sa.select(s.c.formula_version, s.c.score, s.c.scored_at)
                                .where(s.c.session_id == session_id).order_by(s.c.formula_version)).all()
        return [(r.formula_version, r.score, _utc(r.scored_at)) for r in rows]

    def pass_marks(self) -> dict[str, PassMark]:
        with self.engine.connect() as conn:
            rows = conn.execute(sa.select(schema.pass_marks)).all()
        return {r.scene: PassMark.from_evidence(r.scene, r.mark, r.method, r.formula_version, r.evidence) for r in rows}

    def scenes(self) -> list[str]:
        """Every scene with a session or a pass mark."""
        with self.engine.connect() as conn:
            found = set(conn.execute(sa.select(schema.sessions.c.scene).distinct()).scalars())
        return sorted(found | set(self.pass_marks()))

    def trainee_ids(self) -> list[str]:
        with self.engine.connect() as conn:
            return list(conn.execute(sa.select(schema.trainees.c.id).order_by(schema.trainees.c.id)).scalars())

    def cohort(self) -> tuple[list[TraineeSummary], dict[str, list[StoredSession]], dict[str, PassMark]]:
        """Every trainee's standing (by id), their sessions (oldest first) and the scenes' pass marks, read once."""
        with self.engine.connect() as conn:
            people = conn.execute(sa.select(schema.trainees.c.id, schema.trainees.c.name)
                                  .order_by(schema.trainees.c.id)).all()
        by_trainee: dict[str, list[StoredSession]] = {p.id: [] for p in people}
        for s in self.sessions():
            by_trainee[s.trainee].append(s)
        marks = self.pass_marks()
        return [summary(p.id, p.name, by_trainee[p.id], marks) for p in people], by_trainee, marks

    def trainees(self) -> list[TraineeSummary]:
        """Every trainee's standing, by id."""
        return self.cohort()[0]

    def trainee(self, trainee: str) -> tuple[TraineeSummary, list[StoredSession]]:
        """One trainee's standing and sessions (oldest first); an unknown id is refused by name."""
        with self.engine.connect() as conn:
            name = conn.execute(sa.select(schema.trainees.c.name).where(schema.trainees.c.id == trainee)).first()
        if name is None:
            raise ValueError(f"trainee {trainee!r} is not in store {self.url}")
        rows = self.sessions(trainee)
        return summary(trainee, name.name, rows, self.pass_marks()), rows

    def export_csv(self) -> str:
        """Every session as one CSV row: trainee, time, scene, score, its parts, every clinical metric, the
        formula and softenv versions."""
        rows = list(self._export_rows())
        columns = list(dict.fromkeys(k for row in rows for k in row))
        out = io.StringIO()
        writer = csv.DictWriter(out, columns or ["session"], lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
        return out.getvalue()

    def _export_rows(self) -> Iterator[dict[str, Any]]:
        for s in self.sessions():
            r = s.report
            metrics = {k: v for k, v in r["metrics"].items() if k != "clinical"}
            yield {"session": s.id, "trainee": s.trainee, "recorded_at": s.recorded_at.isoformat(), "scene": s.scene,
                   "log": s.log_name, "source": s.source, "score": round(s.score, 3),
                   **{f"part_{k}": r[k] for k in r["weights"]}, **metrics, **r["metrics"].get("clinical", {}),
                   "formula_version": s.formula_version, "softenv_version": s.softenv_version}


def summary(trainee: str, name: str | None, sessions: list[StoredSession], marks: dict[str, PassMark]) -> TraineeSummary:
    """A trainee's standing from their sessions (oldest first) and the scenes' pass marks."""
    if not sessions:
        return TraineeSummary(trainee, name, 0, None, None, None, None, "no sessions")
    scores = np.array([s.score for s in sessions])
    recent = scores[-TREND_SESSIONS:]
    trend = float(np.polyfit(np.arange(len(recent)), recent, 1)[0]) if len(recent) >= 2 else None
    last = sessions[-1]
    mark = marks.get(last.scene)
    status = "no mark" if mark is None else ("pass" if last.score >= mark.mark else "not yet")
    return TraineeSummary(trainee, name, len(sessions), float(scores[-1]), float(scores.max()), trend, last.scene, status)


@contextlib.contextmanager
def log_file(data: bytes, log_name: str) -> Iterator[Path]:
    """A kept log's bytes as a file the log readers take (its suffix, from ``log_name``, names the format)."""
    suffix = Path(log_name).suffix
    if suffix not in (".csv", ".npz"):
        raise ValueError(f"log {log_name!r}: unknown format {suffix!r}; use .csv or .npz")
    with tempfile.TemporaryDirectory(prefix="softenv-log-") as folder:
        path = Path(folder) / f"log{suffix}"
        path.write_bytes(data)
        try:
            yield path
        except ValueError as exc:             # name the log as the lab knows it, not the temporary file
            raise ValueError(str(exc).replace(str(path), log_name)) from None


def score_bytes(data: bytes, log_name: str, scene: dict[str, Any] | None = None,
                scene_named: str | None = None) -> dict[str, Any]:
    """Score a log from its bytes (:func:`softenv.training.scoring.score_file`); the report names the log
    ``log_name``."""
    with log_file(data, log_name) as path:
        report = scoring.score_file(path, scene, scene_named=scene_named)
    report["trajectory"] = log_name
    return report
