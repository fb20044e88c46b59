"""Login, CSRF, bearer tokens, and the JSON API's contract."""

from __future__ import annotations

import re

from dataset.db import transaction
from dataset.services import jobs as job_service
from dataset.services import users as user_service
from tests.conftest import csrf_from, login

API_RULE = re.compile(r"<(?:\w+:)?(\w+)>")


def test_login_logout_and_wrong_password(client) -> None:  # type: ignore[no-untyped-def]
    assert client.get("/").status_code == 302
    response = login(client, "curator", "not-the-password")
    assert response.status_code == 401 and b"Wrong user name or password" in response.data
    response = login(client, "curator")
    assert response.status_code == 302 and response.location == "/"
    page = client.get("/").get_data(as_text=True)
    assert 'data-role="curator"' in page and 'data-nav="users"' not in page and 'data-nav="jobs"' in page
    assert client.post("/logout", data={"csrf_token": csrf_from(page)}).status_code == 302
    assert client.get("/").status_code == 302


def test_login_redirects_only_within_the_site(client) -> None:  # type: ignore[no-untyped-def]
    for target, expected in (("/jobs", "/jobs"), ("https://evil.example/", "/"), ("//evil.example", "/"),
                             ("/%5Cevil.example", "/"), ("/\\evil.example", "/"), ("/%09/evil.example", "/")):
        # each login voids the CSRF token before it: take the one the page shows now
        token = csrf_from(client.get("/login", follow_redirects=True).get_data(as_text=True))
        response = client.post(f"/login?next={target}", data={"name": "admin", "password": "correct-horse-battery",
                                                              "csrf_token": token})
        assert response.location == expected


def test_state_changing_requests_need_csrf_with_a_session(client) -> None:  # type: ignore[no-untyped-def]
    login(client, "admin")
    body = {"name": "newbie", "role": "annotator", "password": "long-enough"}
    response = client.post("/api/v1/users", json=body)
    assert response.status_code == 400 and "CSRF" in response.json["error"]
    response = client.post("/admin/users", data=body)
    assert response.status_code == 400
    token = csrf_from(client.get("/admin/users").get_data(as_text=True))
    assert client.post("/api/v1/users", json=body, headers={"X-CSRFToken": token}).status_code == 201
    response = client.post("/admin/users", data={**body, "name": "newbie2", "csrf_token": token})
    assert response.status_code == 302
    assert b"newbie2" in client.get("/admin/users").data


def test_bearer_tokens_need_no_csrf_and_bad_tokens_get_401(client, tokens) -> None:  # type: ignore[no-untyped-def]
    response = client.post("/api/v1/users", json={"name": "bot", "role": "annotator", "password": "long-enough"},
                           headers={"Authorization": f"Bearer {tokens['admin']}"})
    assert response.status_code == 201 and response.json["name"] == "bot"
    response = client.get("/api/v1/me", headers={"Authorization": "Bearer ist_forged"})
    assert response.status_code == 401 and response.is_json


def test_api_errors_are_json(client, tokens) -> None:  # type: ignore[no-untyped-def]
    auth = {"Authorization": f"Bearer {tokens['admin']}"}
    def create(name: str, role: str):  # type: ignore[no-untyped-def]
        return client.post("/api/v1/users", json={"name": name, "role": role, "password": "long-enough"}, headers=auth)

    cases = [
        (create("admin", "admin"), 409, "already exists"),
        (create("x", "wizard"), 400, "unknown role"),
        (client.post("/api/v1/users", data="not json", headers=auth), 400, "JSON object"),
        (client.get("/api/v1/frames?limit=abc", headers=auth), 400, "integer"),
        (client.get("/api/v1/frames?state=nope", headers=auth), 400, "unknown frame state"),
        (client.get("/api/v1/jobs/999", headers=auth), 404, "no job"),
        (client.get("/api/v1/nothing-here", headers=auth), 404, ""),
        (client.post("/api/v1/jobs/999/retry", headers=auth), 404, "no job"),
        (client.get("/api/v1/jobs?state=bogus", headers=auth), 400, "state must be one of"),
        (client.get("/api/v1/jobs?kind=bogus", headers=auth), 400, "kind must be one of"),
        (client.post("/api/v1/prefilter", json={"video_id": "abc"}, headers=auth), 400, "integer"),
        (client.post("/api/v1/prefilter", json={"backend": "gpt"}, headers=auth), 400, "backend must be"),
        (client.post("/api/v1/frames/1/review", json={"decision": "approve", "revision": "x"}, headers=auth), 400,
         "revision must be"),
    ]
    for response, status, message in cases:
        assert response.status_code == status and response.is_json, (response.status_code, response.data)
        assert message in response.json["error"]


def test_annotators_see_only_their_own_jobs(client, runtime, tokens) -> None:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:
        mine = job_service.create_job(s, "ingest", {}, user_service.get_user(s, "annotator")).id
        theirs = job_service.create_job(s, "ingest", {}, user_service.get_user(s, "admin")).id
        generate = job_service.create_job(s, "generate", {}, user_service.get_user(s, "curator")).id
    def ids(role: str, query: str = "") -> set[int]:
        response = client.get(f"/api/v1/jobs{query}", headers={"Authorization": f"Bearer {tokens[role]}"})
        return {j["id"] for j in response.json["items"]}
    assert ids("annotator") == {mine} and ids("curator") == {mine, theirs, generate}
    # the Ingest page's list: a curator's own ingest jobs, though a curator sees every job
    assert ids("curator", "?kind=ingest") == {mine, theirs} and ids("curator", "?kind=ingest&mine=1") == set()
    assert ids("curator", "?mine=1") == {generate} and ids("admin", "?kind=ingest&mine=1") == {theirs}
    response = client.get(f"/api/v1/jobs/{theirs}", headers={"Authorization": f"Bearer {tokens['annotator']}"})
    assert response.status_code == 404
    job = client.get(f"/api/v1/jobs/{mine}", headers={"Authorization": f"Bearer {tokens['annotator']}"}).json
    assert job["state"] == "queued" and job["progress"] == 0 and "log" in job and job["created_by"] == "annotator"


def test_retry_refuses_jobs_that_did_not_fail(client, runtime, tokens) -> None:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:
        job_id = job_service.create_job(s, "ingest", {}, None).id
    response = client.post(f"/api/v1/jobs/{job_id}/retry", headers={"Authorization": f"Bearer {tokens['curator']}"})
    assert response.status_code == 409 and "only failed or interrupted" in response.json["error"]


def test_openapi_document_lists_exactly_the_api_routes(app, client, tokens) -> None:  # type: ignore[no-untyped-def]
    doc = client.get("/api/v1/openapi.json", headers={"Authorization": f"Bearer {tokens['annotator']}"}).json
    assert doc["openapi"].startswith("3.")
    documented = {(path, method.upper()) for path, ops in doc["paths"].items() for method in ops}
    routed = {(API_RULE.sub(r"{\1}", rule.rule.removeprefix("/api/v1")), method)
              for rule in app.url_map.iter_rules() if rule.rule.startswith("/api/v1")
              for method in rule.methods - {"HEAD", "OPTIONS"}}
    assert documented == routed


def test_healthz_and_funnel(client, tokens) -> None:  # type: ignore[no-untyped-def]
    assert client.get("/healthz").json == {"status": "ok"}
    icon = client.get("/favicon.ico")  # browsers ask before reading the page: no 404 in every console
    assert icon.status_code == 200 and icon.mimetype == "image/svg+xml" and b"<svg" in icon.data
    funnel = client.get("/api/v1/stats/funnel", headers={"Authorization": f"Bearer {tokens['annotator']}"}).json
    assert list(funnel) == ["videos", "frames", "prefiltered", "approved", "annotated", "generated", "accepted"]
