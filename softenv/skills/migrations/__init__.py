"""Alembic migrations of the session store (``versions/``, one file a schema version); ``env.py`` runs
them on the connection :func:`softenv.skills.store.upgrade` hands it."""
