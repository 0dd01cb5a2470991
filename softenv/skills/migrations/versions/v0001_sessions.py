"""Trainees, their sessions (raw logs) and the sessions' scores.

Revision ID: 0001
"""

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None


def upgrade() -> None:
    op.create_table(
        "trainees",
        sa.Column("id", sa.String(64), primary_key=True),
        sa.Column("name", sa.String(200), nullable=True),
        sa.Column("created_at", sa.DateTime(timezone=True), nullable=False),
    )
    op.create_table(
        "sessions",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("trainee_id", sa.String(64), sa.ForeignKey("trainees.id", ondelete="CASCADE"), nullable=False),
        sa.Column("recorded_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("scene", sa.String(400), nullable=False),
        sa.Column("scene_sections", sa.JSON, nullable=False),
        sa.Column("log_kind", sa.String(40), nullable=False),
        sa.Column("log_name", sa.String(255), nullable=False),
        sa.Column("log_bytes", sa.LargeBinary, nullable=False),
        sa.Column("log_sha256", sa.String(64), nullable=False, unique=True),
        sa.Column("source", sa.String(20), nullable=False),
        sa.Column("softenv_version", sa.String(40), nullable=False),
    )
    op.create_index("ix_sessions_trainee_id", "sessions", ["trainee_id"])
    op.create_index("ix_sessions_scene", "sessions", ["scene"])
    op.create_table(
        "scores",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("session_id", sa.Integer, sa.ForeignKey("sessions.id", ondelete="CASCADE"), nullable=False),
        sa.Column("formula_version", sa.Integer, nullable=False),
        sa.Column("score", sa.Float, nullable=False),
        sa.Column("report", sa.JSON, nullable=False),
        sa.Column("softenv_version", sa.String(40), nullable=False),
        sa.Column("scored_at", sa.DateTime(timezone=True), nullable=False),
        sa.UniqueConstraint("session_id", "formula_version", name="uq_scores_session_formula"),
    )
    op.create_index("ix_scores_session_id", "scores", ["session_id"])


def downgrade() -> None:
    op.drop_table("scores")
    op.drop_table("sessions")
    op.drop_table("trainees")
