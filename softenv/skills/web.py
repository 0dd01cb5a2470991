"""The instructor's dashboard (``softenv serve``): server-rendered pages over a session store.

Built on Starlette (routing, Jinja2 templates, background tasks) and served by uvicorn; pages work
without JavaScript but for the forms (which post with the CSRF header) and the progress bar. Pages:

| path | what |
|---|---|
| ``/`` | the cohort: each trainee's sessions, latest and best score, trend, status; every trainee's scores |
| ``/trainees/{id}`` | a trainee: their sessions, the score and each clinical metric over sessions (the expert dashed) |
| ``/sessions/{id}`` | a session: the replay as an animation, the parts against the expert's, the advice |
| ``/upload`` | upload a log: scored (with progress) and kept |
| ``/passmarks`` | each scene's pass mark by the contrasting-groups method, and setting one |
| ``/export.csv`` | the cohort, one row a session |

Security: on a loopback address anyone on the machine may look; on any other address every request
needs the token (``?token=`` once, then a cookie; or ``Authorization: Bearer``). Every state-changing
request (POST) must carry, in a header, the CSRF token of the cookie the dashboard set (starlette-csrf's
signed double submit cookie; the pages' forms post through a few lines of script that add it), so
another site cannot make a browser change the store.
"""

from __future__ import annotations

import functools
import ipaddress
import json
import secrets
from dataclasses import dataclass, field
from datetime import timezone
from importlib.resources import files
from pathlib import Path
from typing import Any, Callable

from starlette.applications import Starlette
from starlette.background import BackgroundTask
from starlette.requests import Request
from starlette.responses import HTMLResponse, JSONResponse, PlainTextResponse, RedirectResponse, Response
from starlette.routing import Route
from starlette.templating import Jinja2Templates
from starlette_csrf import CSRFMiddleware
from starlette.types import ASGIApp, Receive, Scope, Send

from .. import __version__
from ..training.logs import HAND_LOG
from . import views
from .passmark import contrasting_groups
from .store import Store, StoredSession

TEMPLATES = Jinja2Templates(directory=str(files(__package__ or "softenv.skills") / "templates"))
TEMPLATES.env.filters["when"] = lambda d: d.astimezone(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
TOKEN_COOKIE = "softenv_token"


def is_loopback(host: str) -> bool:
    """Whether ``host`` is a loopback address (``localhost`` included): the dashboard's open default."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@dataclass
class Job:
    """A long task (scoring an upload, rescoring, a pass mark): its progress, and where it leads when done."""

    id: str
    title: str
    done: int = 0
    total: int = 0
    stage: str = ""
    state: str = "running"                # "running", "done" or "failed"
    error: str = ""
    result_url: str = ""

    def progress(self, done: int, total: int, stage: str = "") -> None:
        self.done, self.total, self.stage = done, total, stage or self.stage


@dataclass
class Dashboard:
    """The app's state: the store and its running jobs."""

    store: Store
    jobs: dict[str, Job] = field(default_factory=dict)

    def start(self, title: str, work: Callable[[Job], str]) -> tuple[Job, BackgroundTask]:
        """A job running ``work(job)`` (which returns the page to go to when done) after the response."""
        job = Job(secrets.token_urlsafe(8), title)
        self.jobs[job.id] = job

        def run() -> None:
            try:
                job.result_url = work(job)
                job.state = "done"
            except ValueError as exc:          # bad input: its one line is the message
                job.error, job.state = str(exc), "failed"
        return job, BackgroundTask(run)


def _page(request: Request, template: str, status_code: int = 200, **context: Any) -> HTMLResponse:
    return TEMPLATES.TemplateResponse(request, template, {"version": __version__, **context}, status_code=status_code)


def _board(request: Request) -> Dashboard:
    board: Dashboard = request.app.state.board
    return board


async def cohort(request: Request) -> Response:
    trainees, sessions, marks = _board(request).store.cohort()
    count = sum(map(len, sessions.values()))
    return _page(request, "cohort.html", trainees=trainees, marks=marks, sessions=count,
                 plot=views.cohort_svg(sessions, marks) if count else "")


async def trainee(request: Request) -> Response:
    store = _board(request).store
    try:
        standing, rows = store.trainee(request.path_params["trainee"])
    except ValueError as exc:
        return _page(request, "message.html", 404, title="No such trainee", message=str(exc))
    mark = store.pass_marks().get(rows[-1].scene) if rows else None
    return _page(request, "trainee.html", trainee=standing, sessions=rows, mark=mark,
                 plot=views.trainee_svg(rows, mark) if rows else "")


def _session_or_404(request: Request) -> StoredSession | Response:
    try:
        return _board(request).store.session(int(request.path_params["session"]))
    except ValueError as exc:
        return _page(request, "message.html", 404, title="No such session", message=str(exc))


async def session(request: Request) -> Response:
    found = _session_or_404(request)
    if isinstance(found, Response):
        return found
    store = _board(request).store
    return _page(request, "session.html", s=found, r=found.report, parts=views.parts_svg(found.report),
                 history=store.score_history(found.id), metrics=views.metrics_of(found.report),
                 expert=views.metrics_of(found.report, "expert"), labels=views.METRIC_LABELS)


def session_replay(request: Request) -> Response:
    found = _session_or_404(request)
    if isinstance(found, Response):
        return found
    name, data = _board(request).store.raw_log(found.id)
    gif = _replay(name, data, json.dumps(found.report["scene"], sort_keys=True))
    return Response(gif, media_type="image/gif", headers={"Cache-Control": "private, max-age=3600"})


@functools.lru_cache(maxsize=16)
def _replay(name: str, data: bytes, scene_json: str) -> bytes:
    """A kept log's animation, drawn once a process (a second or two)."""
    return views.replay_gif(name, data, json.loads(scene_json) or None)


def session_log(request: Request) -> Response:
    found = _session_or_404(request)
    if isinstance(found, Response):
        return found
    name, data = _board(request).store.raw_log(found.id)
    return Response(data, media_type="text/csv" if name.endswith(".csv") else "application/octet-stream",
                    headers={"Content-Disposition": f'attachment; filename="session{found.id}_{Path(name).name}"'})


async def upload(request: Request) -> Response:
    board = _board(request)
    if request.method == "GET":
        return _page(request, "upload.html", trainees=board.store.trainee_ids(), error="")
    async with request.form(max_files=1, max_fields=8) as form:
        trainee_id = str(form.get("trainee", "")).strip()
        log = form.get("log")
        if log is None or isinstance(log, str) or not log.filename:
            return _page(request, "upload.html", 400, trainees=board.store.trainee_ids(),
                         error="choose a log file (.csv or .npz) to upload")
        data, name = await log.read(), Path(log.filename).name

    def work(job: Job) -> str:
        job.progress(0, 1, "scoring")
        kept = board.store.add(data, trainee_id, log_name=name, source="upload")
        job.progress(1, 1, "kept")
        return f"/sessions/{kept.id}"

    job, task = board.start(f"Scoring {name} for {trainee_id}", work)
    return RedirectResponse(f"/jobs/{job.id}", status_code=303, background=task)


async def rescore(request: Request) -> Response:
    board = _board(request)

    def work(job: Job) -> str:
        board.store.rescore(lambda d, t: job.progress(d, t, "rescoring"))
        return "/"

    job, task = board.start("Rescoring every session under the current formula", work)
    return RedirectResponse(f"/jobs/{job.id}", status_code=303, background=task)


async def passmarks(request: Request) -> Response:
    board = _board(request)
    if request.method == "GET":
        return _page(request, "passmarks.html", marks=board.store.pass_marks(), scenes=board.store.scenes())
    async with request.form(max_fields=4) as form:
        scene = str(form.get("scene", ""))
    sessions = [s for s in board.store.sessions() if s.scene == scene]
    if not sessions or sessions[0].log_kind != HAND_LOG.name:
        return _page(request, "passmarks.html", 400, marks=board.store.pass_marks(), scenes=board.store.scenes(),
                     error=f"scene {scene!r}: a pass mark needs a hand-pose scene with kept sessions "
                           "(the profiles are hand-pose trainees)")
    sections = sessions[0].report["scene"] or None

    def work(job: Job) -> str:
        board.store.set_pass_mark(contrasting_groups(scene, sections, progress=lambda d, t: job.progress(d, t, "scoring "
                                                                                                           "the groups")))
        return "/passmarks"

    job, task = board.start(f"Pass mark for {scene} (contrasting groups)", work)
    return RedirectResponse(f"/jobs/{job.id}", status_code=303, background=task)


async def delete_trainee(request: Request) -> Response:
    board = _board(request)
    tid = request.path_params["trainee"]
    async with request.form(max_fields=4) as form:
        confirm = str(form.get("confirm", ""))
    if confirm != tid:
        return _page(request, "message.html", 400, title="Not deleted",
                     message=f"type the trainee's id ({tid}) to confirm deleting their data")
    try:
        gone = board.store.delete_trainee(tid)
    except ValueError as exc:
        return _page(request, "message.html", 404, title="Not deleted", message=str(exc))
    return _page(request, "message.html", title="Deleted",
                 message=f"trainee {tid} and their {gone} sessions, raw logs and scores are deleted")


async def job_page(request: Request) -> Response:
    job = _board(request).jobs.get(request.path_params["job"])
    if job is None:
        return _page(request, "message.html", 404, title="No such job", message="this job is not known (the server may "
                     "have restarted)")
    return _page(request, "job.html", job=job)


async def job_status(request: Request) -> Response:
    job = _board(request).jobs.get(request.path_params["job"])
    if job is None:
        return JSONResponse({"state": "unknown"}, status_code=404)
    return JSONResponse({"state": job.state, "done": job.done, "total": job.total, "stage": job.stage,
                         "error": job.error, "url": job.result_url})


async def export(request: Request) -> Response:
    return PlainTextResponse(_board(request).store.export_csv(), media_type="text/csv",
                             headers={"Content-Disposition": 'attachment; filename="cohort.csv"'})


class TokenGate:
    """Every request needs ``token`` (off a loopback address): ``?token=`` once sets a cookie and drops it
    from the address; the cookie or ``Authorization: Bearer`` after that."""

    def __init__(self, app: ASGIApp, token: str) -> None:
        self.app, self.token = app, token

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        request = Request(scope)
        given = request.query_params.get("token")
        if given is not None and secrets.compare_digest(given, self.token):
            response: Response = RedirectResponse(request.url.remove_query_params("token").path, status_code=303)
            response.set_cookie(TOKEN_COOKIE, self.token, httponly=True, samesite="strict")
        elif any(secrets.compare_digest(c, self.token) for c in (request.cookies.get(TOKEN_COOKIE, ""),
                 request.headers.get("authorization", "").removeprefix("Bearer "))):
            await self.app(scope, receive, send)
            return
        else:
            response = PlainTextResponse("this dashboard needs its token: open the address softenv serve printed "
                                         "(it ends in ?token=...)", status_code=401)
        await response(scope, receive, send)


def make_app(store: Store, token: str | None = None) -> ASGIApp:
    """The dashboard over ``store``; with ``token``, every request must carry it (see :class:`TokenGate`)."""
    app = Starlette(routes=[
        Route("/", cohort), Route("/trainees/{trainee}", trainee),
        Route("/trainees/{trainee}/delete", delete_trainee, methods=["POST"]),
        Route("/sessions/{session:int}", session), Route("/sessions/{session:int}/replay.gif", session_replay),
        Route("/sessions/{session:int}/log", session_log),
        Route("/upload", upload, methods=["GET", "POST"]), Route("/rescore", rescore, methods=["POST"]),
        Route("/passmarks", passmarks, methods=["GET", "POST"]),
        Route("/jobs/{job}", job_page), Route("/jobs/{job}/status", job_status),
        Route("/export.csv", export),
    ])
    app.state.board = Dashboard(store)
    protected: ASGIApp = CSRFMiddleware(app, secret=secrets.token_hex(32), cookie_samesite="strict")
    return TokenGate(protected, token) if token else protected
