"""Build the skills lab's demo cohort (``softenv.skills.cohort``, what ``softenv serve --demo`` opens),
serve it, and screenshot every page of the dashboard in headless Chromium (Debian's, through
Playwright) into ``results/skills_lab/``, with the cohort as CSV and a README naming the command and
commit. Run it from a clean commit.

    python scripts/make_skills_lab.py [--out results/skills_lab]
"""

from __future__ import annotations

import argparse
import shlex
import shutil
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path

import uvicorn
from playwright.sync_api import sync_playwright

from softenv._artifact import write_text
from softenv.bench.timing import code_revision
from softenv.skills import cohort, web
from softenv.skills.store import Store
from softenv.training.logs import example_log

ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
        "--disable-component-update", "--disable-sync"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/skills_lab"))
    args = parser.parse_args()
    started = time.perf_counter()
    demo = cohort.demo_store(progress=lambda stage, done, total: print(f"{stage} {done}/{total}", end="\r"))
    built_s = time.perf_counter() - started
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "demo.sqlite"
        shutil.copyfile(demo, path)
        store = Store(path)
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        server = uvicorn.Server(uvicorn.Config(web.make_app(store), host="127.0.0.1", port=port, log_level="warning"))
        thread = threading.Thread(target=server.run, daemon=True)
        thread.start()
        while not server.started:
            time.sleep(0.1)
        base = f"http://127.0.0.1:{port}"
        args.out.mkdir(parents=True, exist_ok=True)
        trainee = store.trainees()[0].id
        last = store.sessions(trainee)[-1].id
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=shutil.which("chromium"), args=ARGS)
            page = browser.new_page(viewport={"width": 1200, "height": 900})
            shots = [("cohort", "/"), ("trainee", f"/trainees/{trainee}"), ("session", f"/sessions/{last}"),
                     ("passmarks", "/passmarks")]
            for name, url in shots:
                page.goto(base + url)
                if name == "session":
                    page.wait_for_function("() => { const i = document.getElementById('replay'); "
                                           "return i.complete && i.naturalWidth > 0; }", timeout=120_000)
                page.screenshot(path=str(args.out / f"{name}.png"), full_page=True)
            page.goto(base + "/upload")                       # an upload, shown while it is scored
            page.fill("input[name=trainee]", "T-13")
            page.set_input_files("input[name=log]", str(example_log("device_logs/levers_on_teeth")))
            page.screenshot(path=str(args.out / "upload.png"), full_page=True)
            page.click("#submit")
            page.wait_for_url("**/sessions/*", timeout=120_000)
            browser.close()
        server.should_exit = True
        thread.join()
        write_text(args.out / "cohort.csv", store.export_csv())
        marks = store.pass_marks()
        summary = store.trainees()
        store.close()
    command = "python " + " ".join(shlex.quote(a) for a in sys.argv)
    mark = next(iter(marks.values()))
    rows = "\n".join(f"| {t.id} | {t.sessions} | {t.latest:.1f} | {t.best:.1f} | {t.trend:+.1f} | {t.status} |"
                     for t in summary if t.latest is not None and t.best is not None and t.trend is not None)
    write_text(args.out / "README.md", f"""# The skills lab's demo cohort

Made by `{command}` at commit `{code_revision()}`; the cohort built in {built_s:.0f} s (or read from the cache).
Screenshots of each page of `softenv serve --demo` in headless Chromium: `cohort.png`, `trainee.png`,
`session.png`, `passmarks.png`, `upload.png` (a log chosen for trainee T-13; it is then scored and kept,
so `cohort.csv` has 121 sessions). How the cohort is made: docs/skills-lab.md.

Pass mark on {mark.scene} (contrasting groups, {len(mark.groups['expert'])} + {len(mark.groups['novice'])} members):
**{mark.mark:.1f}**; false pass {100 * mark.false_pass:.0f} %, false fail {100 * mark.false_fail:.0f} %.

| trainee | sessions | latest | best | trend (points a session) | status |
|---|---|---|---|---|---|
{rows}
""")
    print(f"\nwrote {args.out}/: cohort.png, trainee.png, session.png, passmarks.png, upload.png, cohort.csv, README.md")


if __name__ == "__main__":
    main()
