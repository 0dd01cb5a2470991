"""Pass marks per scene (the contrasting-groups method's mark and its evidence).

Revision ID: 0002
Revises: 0001
"""

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"


def upgrade() -> None:
    op.create_table(
        "pass_marks",
        sa.Column("scene", sa.String(400), primary_key=True),
        sa.Column("mark", sa.Float, nullable=False),
        sa.Column("method", sa.String(40), nullable=False),
        sa.Column("formula_version", sa.Integer, nullable=False),
        sa.Column("evidence", sa.JSON, nullable=False),
        sa.Column("set_at", sa.DateTime(timezone=True), nullable=False),
    )


def downgrade() -> None:
    op.drop_table("pass_marks")
