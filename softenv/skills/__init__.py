"""The skills lab: trainees' sessions kept in a database, pass marks, and an instructor's dashboard.

* :mod:`.schema` -- the store's tables; :mod:`.migrations` -- how each schema version is reached (Alembic).
* :mod:`.store` -- the session store: keep a scored session, rescore, export, delete a trainee.
* :mod:`.passmark` -- pass marks by the contrasting-groups method on the published profiles.
* :mod:`.cohort` -- a demo cohort: trainees of the published profiles learning over sessions.
* :mod:`.views` -- what the dashboard draws: plots as SVG, a session's replay as an animation.
* :mod:`.web` -- the dashboard (``softenv serve``): Starlette pages over a store.
"""
