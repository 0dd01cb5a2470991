"""`softenv serve --demo` in a real headless Chromium (Debian's, driven by Playwright): the cohort, a
trainee, a session's replay, an upload that appears, the CSV download, a bad upload refused in one line."""

import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from playwright.sync_api import sync_playwright

from softenv.training.logs import example_log

ROOT = Path(__file__).resolve().parents[1]
# as root in a closed network: no sandbox, and none of Chromium's background connections
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]


def chromium() -> str:
    path = shutil.which("chromium")
    if path is None:
        pytest.fail("Debian's chromium is not installed: run `bash scripts/test_services.sh` (the README's test command does)")
    return path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def serve(*args: str, timeout: float = 900.0) -> tuple[subprocess.Popen, str]:
    """``softenv serve ARGS`` on a free loopback port, once it answers (the demo cohort builds first)."""
    port = free_port()
    process = subprocess.Popen([sys.executable, "-m", "softenv", "serve", "--port", str(port), *args], cwd=ROOT,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                               env={**os.environ, "PYTHONPATH": str(ROOT)})
    base, end = f"http://127.0.0.1:{port}", time.monotonic() + timeout
    while True:
        assert process.poll() is None, process.communicate()[0]
        assert time.monotonic() < end, "softenv serve never answered"
        try:
            urllib.request.urlopen(base + "/", timeout=5)
            return process, base
        except urllib.error.HTTPError:                 # it answers (a 401 where a token is needed)
            return process, base
        except OSError:
            time.sleep(0.5)


@pytest.mark.slow
def test_the_demo_dashboard_works_in_a_real_browser(tmp_path):
    process, base = serve("--demo")
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium(), args=CHROMIUM_ARGS)
            page = browser.new_page(accept_downloads=True)
            page.goto(base + "/")
            assert page.locator("#cohort tr").count() == 13                         # the header and 12 trainees
            assert page.locator(".plot svg").count() == 1 and "Pass mark on SoftSphereHaptic-v0" in page.inner_text("main")
            page.click("#cohort a >> text=T-01")
            page.wait_for_url("**/trainees/T-01")
            assert page.locator("#sessions tr").count() == 11 and page.locator(".plot svg").count() == 1
            page.click("#sessions a >> nth=-1")
            page.wait_for_url("**/sessions/*")
            page.wait_for_function("() => { const i = document.getElementById('replay'); "
                                   "return i.complete && i.naturalWidth == 640; }", timeout=120_000)
            assert page.locator("#parts tr").count() == 7 and page.locator("#advice li").count() >= 1

            page.goto(base + "/upload")
            page.fill("input[name=trainee]", "T-99")
            page.set_input_files("input[name=log]", str(example_log("device_logs/levers_on_teeth")))
            page.click("#submit")
            page.wait_for_url("**/sessions/*", timeout=120_000)
            assert "score" in page.inner_text("h1") and "T-99" in page.inner_text("main")
            page.goto(base + "/")
            assert page.locator("#cohort tr").count() == 14 and page.locator("#cohort a >> text=T-99").count() == 1

            with page.expect_download() as download:
                page.click("header >> text=Export CSV")
            rows = Path(download.value.path()).read_text().splitlines()
            assert len(rows) == 1 + 12 * 10 + 1 and sum(",T-99," in r for r in rows) == 1

            bad = tmp_path / "cut.csv"
            text = example_log("device_logs/too_forceful").read_text()
            bad.write_text(text[: len(text) // 3].rsplit(",", 1)[0])
            page.goto(base + "/upload")
            page.fill("input[name=trainee]", "T-98")
            page.set_input_files("input[name=log]", str(bad))
            page.click("#submit")
            error = page.locator("#error")
            error.wait_for(state="visible", timeout=60_000)
            assert "cut.csv" in error.inner_text() and "fields; the header has 5" in error.inner_text()
            assert "\n" not in error.inner_text().strip()
            page.goto(base + "/")
            assert page.locator("#cohort tr").count() == 14                         # nothing kept for T-98

            page.goto(base + "/passmarks")
            assert page.locator("#marks tr").count() == 2
            browser.close()
    finally:
        process.terminate()
        process.communicate(timeout=30)                # reads and closes its pipe


def test_a_token_is_asked_for_once_then_kept_in_a_cookie(tmp_path):
    process, base = serve("--store", str(tmp_path / "lab.sqlite"), "--token", "lab-token-1")
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium(), args=CHROMIUM_ARGS)
            page = browser.new_page()
            assert page.goto(base + "/").status == 401 and "needs its token" in page.inner_text("body")
            page.goto(base + "/?token=lab-token-1")
            assert page.url == base + "/" and page.locator("#cohort").count() == 1
            assert page.goto(base + "/passmarks").status == 200
            browser.close()
    finally:
        process.terminate()
        process.communicate(timeout=30)                # reads and closes its pipe
