"""When an admin changes an account, the user's open tab learns why its session ended: the login page
it lands on says so, and so does the answer a page's script asks for when a request was refused."""

from __future__ import annotations

from datetime import timedelta

from sqlalchemy import update

from dataset.db import transaction
from dataset.services import users as user_service
from dataset.tables import Role, UserSession, utcnow
from tests.conftest import csrf_from, login


def change(runtime, name: str, how) -> None:  # type: ignore[no-untyped-def]
    with transaction(runtime.sessions) as s:
        admin = user_service.get_user(s, "admin")
        how(s, admin.id, user_service.get_user(s, name))


def test_a_new_password_is_named_on_the_next_page_and_to_the_open_tab(client, runtime) -> None:  # type: ignore[no-untyped-def]
    login(client, "curator")
    assert client.get("/login/ended").json == {"reason": None, "then": None}  # logged in: nothing ended
    change(runtime, "curator", lambda s, admin, user: user_service.reset_password(s, admin, user, "a-new-password-1"))
    assert client.get("/api/v1/jobs").status_code == 401  # a page's poll is refused…
    said = client.get("/login/ended").json  # …and its banner asks why
    assert said["reason"].startswith("Your session ended because your password was changed (by admin, ")
    assert said["then"] == "log in with the new password"
    page = client.get("/jobs", follow_redirects=True).get_data(as_text=True)  # a click lands on the login page
    assert 'id="session-reason"' in page and "your password was changed (by admin" in page
    assert login(client, "curator", "a-new-password-1").status_code == 302
    assert client.get("/login/ended").json["reason"] is None


def test_a_role_change_and_a_deactivation_say_so(app, runtime) -> None:  # type: ignore[no-untyped-def]
    client = app.test_client()
    login(client, "annotator")
    change(runtime, "annotator", lambda s, admin, user: user_service.set_role(s, admin, user, Role.curator))
    assert "your role was changed to curator" in client.get("/login/ended").json["reason"]
    login(client, "annotator")
    change(runtime, "annotator", lambda s, admin, user: user_service.set_active(s, admin, user, False))
    said = client.get("/login/ended").json
    assert "your account was deactivated (by admin" in said["reason"] and "reactivated" in said["then"]


def test_no_reason_without_an_ended_session_or_for_a_change_before_the_login(app, runtime) -> None:  # type: ignore[no-untyped-def]
    stranger = app.test_client()
    assert stranger.get("/login/ended").json["reason"] is None
    assert 'id="session-reason"' not in stranger.get("/login").get_data(as_text=True)
    change(runtime, "curator", lambda s, admin, user: user_service.reset_password(s, admin, user, "a-new-password-2"))
    client = app.test_client()
    login(client, "curator", "a-new-password-2")
    token = csrf_from(client.get("/").get_data(as_text=True))
    client.post("/logout", data={"csrf_token": token})
    assert client.get("/login/ended").json["reason"] is None  # logged out here: no surprise to explain


def test_a_session_past_its_lifetime_says_how_long_sessions_last(client, runtime) -> None:  # type: ignore[no-untyped-def]
    login(client, "annotator")
    old = utcnow() - timedelta(hours=runtime.settings.session_lifetime_hours + 1)
    with client.session_transaction() as cookie:
        cookie["signed_in_at"] = old.isoformat()
    with transaction(runtime.sessions) as s:
        s.execute(update(UserSession).values(created_at=old))
    assert client.get("/api/v1/me").status_code == 401
    said = client.get("/login/ended").json
    assert f"{runtime.settings.session_lifetime_hours} hours after you logged in" in said["reason"]
