"""The session store's tables (SQLAlchemy Core), as the newest migration leaves them.

:mod:`softenv.skills.migrations` builds them step by step; a test holds the two to each other
(Alembic's ``compare_metadata``), so the tables the store reads are the ones its migrations make.

| table | one row per | keeps |
|---|---|---|
| ``trainees`` | trainee | the lab's pseudonymous id; a name only if the lab adds one |
| ``sessions`` | scored log | trainee, when it was recorded, the scene, the raw log byte for byte (and its SHA-256, unique: a log is kept once), where it came from, the softenv version that stored it |
| ``scores`` | session and formula version | the score, its parts, the expert's parts, the trainee's metrics (every clinical one) and the expert's, the advice |
| ``pass_marks`` | scene | the mark, the method that set it and its evidence (the groups' scores) |
"""

from __future__ import annotations

from sqlalchemy import (JSON, Column, DateTime, Float, ForeignKey, Integer, LargeBinary, MetaData, String, Table,
                        UniqueConstraint)

metadata = MetaData()

trainees = Table(
    "trainees", metadata,
    Column("id", String(64), primary_key=True),
    Column("name", String(200), nullable=True),
    Column("created_at", DateTime(timezone=True), nullable=False),
)

sessions = Table(
    "sessions", metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("trainee_id", String(64), ForeignKey("trainees.id", ondelete="CASCADE"), nullable=False, index=True),
    Column("recorded_at", DateTime(timezone=True), nullable=False),
    Column("scene", String(400), nullable=False, index=True),
    Column("scene_sections", JSON, nullable=False),
    Column("log_kind", String(40), nullable=False),
    Column("log_name", String(255), nullable=False),
    Column("log_bytes", LargeBinary, nullable=False),
    Column("log_sha256", String(64), nullable=False, unique=True),
    Column("source", String(20), nullable=False),
    Column("softenv_version", String(40), nullable=False),
)

scores = Table(
    "scores", metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("session_id", Integer, ForeignKey("sessions.id", ondelete="CASCADE"), nullable=False, index=True),
    Column("formula_version", Integer, nullable=False),
    Column("score", Float, nullable=False),
    Column("report", JSON, nullable=False),
    Column("softenv_version", String(40), nullable=False),
    Column("scored_at", DateTime(timezone=True), nullable=False),
    UniqueConstraint("session_id", "formula_version", name="uq_scores_session_formula"),
)

pass_marks = Table(
    "pass_marks", metadata,
    Column("scene", String(400), primary_key=True),
    Column("mark", Float, nullable=False),
    Column("method", String(40), nullable=False),
    Column("formula_version", Integer, nullable=False),
    Column("evidence", JSON, nullable=False),
    Column("set_at", DateTime(timezone=True), nullable=False),
)
