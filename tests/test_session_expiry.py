"""An ended session, as a browser and as a script meet it: plain words for the one, the how-to for the
other, and a way back to the same page after logging in again."""

from __future__ import annotations

from tests.conftest import PASSWORD, csrf_from, login


def test_a_browser_whose_session_ended_is_told_so_plainly(app, client) -> None:  # type: ignore[no-untyped-def]
    login(client, "curator")
    token = csrf_from(client.get("/").get_data(as_text=True))
    client.post("/logout", data={"csrf_token": token})
    response = client.get("/api/v1/frames", headers={"X-CSRFToken": token})
    assert response.status_code == 401
    assert response.get_json() == {"error": "Your session ended — log in again.", "status": 401}


def test_scripts_still_get_the_how_to(app, tokens) -> None:  # type: ignore[no-untyped-def]
    from webapp.auth import BAD_TOKEN

    script = app.test_client()
    for headers, message in (({}, "authentication required: log in or send 'Authorization: Bearer <token>'"),
                             ({"Authorization": "Bearer ist_not-a-token"}, BAD_TOKEN)):
        response = script.get("/api/v1/frames", headers=headers)
        assert response.status_code == 401
        assert response.get_json()["error"] == message
    assert "illusion-studio users token NAME" in BAD_TOKEN


def test_log_in_again_returns_to_the_page_and_only_to_this_site(app, client) -> None:  # type: ignore[no-untyped-def]
    page = "/frames?state=approved&offset=60&after=1-60"
    assert client.get("/frames?state=approved").headers["Location"].startswith("/login?next=")
    form = csrf_from(client.get("/login").get_data(as_text=True))
    response = client.post("/login?next=" + page.replace("&", "%26"),
                           data={"name": "annotator", "password": PASSWORD, "csrf_token": form})
    assert response.status_code == 302 and response.headers["Location"] == page
    # Logged in again in another tab: the banner's link goes straight back, never off the site.
    assert client.get("/login?next=" + page.replace("&", "%26")).headers["Location"] == page
    for evil in ("//evil.example/x", "/\\evil.example", "https://evil.example/", "/\tevil"):
        assert client.get("/login", query_string={"next": evil}).headers["Location"] == "/"
