"""Shared by the skills-lab tests: a fresh store on SQLite or on the real PostgreSQL that
scripts/test_services.sh starts (the README's test command runs it first)."""

from __future__ import annotations

import os
import uuid
from pathlib import Path
from typing import Iterator

import pytest
import sqlalchemy as sa

POSTGRES = os.environ.get("SOFTENV_TEST_POSTGRES", "postgresql+psycopg://softenv:softenv@localhost:5432/softenv_test")
BACKENDS = ("sqlite", "postgresql")


def _admin() -> object:
    engine = sa.create_engine(POSTGRES, isolation_level="AUTOCOMMIT")
    try:
        with engine.connect() as conn:
            conn.execute(sa.text("SELECT 1"))
    except sa.exc.OperationalError as exc:
        pytest.fail(f"PostgreSQL is not reachable at {POSTGRES} ({exc.orig}): run `bash scripts/test_services.sh` "
                    "(the README's test command does), or point SOFTENV_TEST_POSTGRES at a server")
    return engine


def fresh_url(backend: str, tmp_path: Path) -> Iterator[str]:
    """A URL of an empty database of ``backend``, dropped afterwards (PostgreSQL: a database of its own)."""
    if backend == "sqlite":
        yield str(tmp_path / "lab.sqlite")
        return
    admin = _admin()
    name = f"softenv_t_{uuid.uuid4().hex[:12]}"
    with admin.connect() as conn:                       # type: ignore[attr-defined]
        conn.execute(sa.text(f'CREATE DATABASE "{name}"'))
    try:
        yield POSTGRES.rsplit("/", 1)[0] + "/" + name
    finally:
        with admin.connect() as conn:                   # type: ignore[attr-defined]
            conn.execute(sa.text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.dispose()                                 # type: ignore[attr-defined]
