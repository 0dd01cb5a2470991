"""The dashboard's pages, token and CSRF protection, through Starlette's test client (the browser
tests drive the same pages in Chromium: test_skills_browser.py)."""

import pytest
from starlette.testclient import TestClient

from softenv.skills.store import Store
from softenv.skills.web import is_loopback, make_app
from softenv.training.logs import example_log


@pytest.fixture
def store(tmp_path):
    with Store(tmp_path / "lab.sqlite") as store:
        store.add(example_log("device_logs/levers_on_teeth"), "T-1")
        store.add(example_log("trajectories/too_forceful"), "T-2")
        yield store


def test_loopback_addresses_are_open_others_need_the_token():
    assert all(map(is_loopback, ["127.0.0.1", "localhost", "::1", "127.5.0.1"]))
    assert not any(map(is_loopback, ["0.0.0.0", "192.168.1.10", "::", "lab.example.org"]))


def test_every_page_renders_for_both_kinds_of_log(store):
    client = TestClient(make_app(store))
    for path, words in [("/", "T-2"), ("/trainees/T-1", "Delete this trainee"), ("/sessions/1", "lever"),
                        ("/sessions/2", "jerk"), ("/passmarks", "contrasting-groups"), ("/upload", "Score and keep")]:
        page = client.get(path)
        assert page.status_code == 200 and words in page.text, path
        assert ("<svg" in page.text) == (path in ("/", "/trainees/T-1", "/sessions/1", "/sessions/2")), path
    gif = client.get("/sessions/1/replay.gif")
    assert gif.status_code == 200 and gif.content[:6] == b"GIF89a" and gif.headers["content-type"] == "image/gif"
    assert client.get("/sessions/1/log").content == example_log("device_logs/levers_on_teeth").read_bytes()
    assert client.get("/sessions/99").status_code == 404 and client.get("/trainees/T-99").status_code == 404


def test_a_token_gates_every_request_off_loopback(store):
    client = TestClient(make_app(store, token="s3cret-token"), follow_redirects=False)
    assert client.get("/").status_code == 401 and client.get("/export.csv").status_code == 401
    assert client.get("/?token=wrong").status_code == 401
    entry = client.get("/trainees/T-1?token=s3cret-token")
    assert entry.status_code == 303 and entry.headers["location"] == "/trainees/T-1"
    assert client.get("/").status_code == 200                                     # the cookie it set
    bare = TestClient(make_app(store, token="s3cret-token"))
    assert bare.get("/", headers={"Authorization": "Bearer s3cret-token"}).status_code == 200


def test_a_post_without_the_csrf_token_changes_nothing(store):
    client = TestClient(make_app(store), follow_redirects=False)
    client.get("/")                                                               # the CSRF cookie
    for path, data in [("/trainees/T-1/delete", {"confirm": "T-1"}), ("/rescore", {}), ("/upload", {"trainee": "T-3"})]:
        assert client.post(path, data=data).status_code == 403
        assert client.post(path, data=data, headers={"x-csrftoken": "forged"}).status_code == 403
    assert [t.id for t in store.trainees()] == ["T-1", "T-2"]
    token = client.cookies["csrftoken"]
    refused = client.post("/trainees/T-1/delete", data={"confirm": "T-one"}, headers={"x-csrftoken": token})
    assert refused.status_code == 400 and "to confirm deleting their data" in refused.text
    done = client.post("/trainees/T-1/delete", data={"confirm": "T-1"}, headers={"x-csrftoken": token})
    assert done.status_code == 200 and [t.id for t in store.trainees()] == ["T-2"]


def test_the_export_is_the_stores(store):
    client = TestClient(make_app(store))
    csv = client.get("/export.csv")
    assert csv.text == store.export_csv() and "attachment" in csv.headers["content-disposition"]
