"""Server-side sessions that end, login throttling, and admins managing accounts."""

from __future__ import annotations

import hashlib
import re
import secrets
from datetime import timedelta
from pathlib import Path

from click.testing import CliRunner
from sqlalchemy import select, update

from dataset.db import migrate, transaction
from dataset.services import users as user_service
from dataset.tables import ApiToken, AuditEntry, Role, User, UserSession, utcnow
from tests.conftest import PASSWORD, csrf_from, login, make_settings
from webapp.cli import main as cli
from webapp.runtime import Runtime


def user_id(runtime, name: str) -> int:  # type: ignore[no-untyped-def]
    with runtime.sessions() as s:
        return user_service.get_user(s, name).id


def test_a_cookie_saved_before_logout_is_worthless_after_it(app, client) -> None:  # type: ignore[no-untyped-def]
    login(client, "curator")
    saved = client.get_cookie("session").value
    assert client.get("/api/v1/me").status_code == 200
    token = csrf_from(client.get("/").get_data(as_text=True))
    assert client.post("/logout", data={"csrf_token": token}).status_code == 302
    thief = app.test_client()
    thief.set_cookie("session", saved)
    assert thief.get("/api/v1/me").status_code == 401
    assert thief.post("/api/v1/review/bulk", json={"items": [], "decision": "approve"}).status_code in (400, 401)


def test_password_reset_role_change_and_deactivation_end_sessions(app, runtime) -> None:  # type: ignore[no-untyped-def]
    uid = user_id(runtime, "annotator")
    changes = [lambda s, u: user_service.reset_password(s, None, u, "another-password"),
               lambda s, u: user_service.set_role(s, None, u, Role.curator),
               lambda s, u: user_service.set_active(s, None, u, False)]
    for change in changes:
        with transaction(runtime.sessions) as s:
            user = s.get(User, uid)
            user.active, user.password_hash = True, user_service.generate_password_hash(PASSWORD)
        client = app.test_client()
        login(client, "annotator")
        assert client.get("/api/v1/me").status_code == 200
        with transaction(runtime.sessions) as s:
            change(s, s.get(User, uid))
        assert client.get("/api/v1/me").status_code == 401  # on the very next request


def test_idle_and_absolute_lifetimes_end_a_session(client, runtime) -> None:  # type: ignore[no-untyped-def]
    idle = timedelta(minutes=runtime.settings.session_idle_minutes + 1)
    lifetime = timedelta(hours=runtime.settings.session_lifetime_hours + 1)
    for column, age in ((UserSession.last_seen_at, idle), (UserSession.created_at, lifetime)):
        login(client, "annotator")
        assert client.get("/api/v1/me").status_code == 200
        with transaction(runtime.sessions) as s:
            s.execute(update(UserSession).values({column: utcnow() - age}))
        assert client.get("/api/v1/me").status_code == 401
        with runtime.sessions() as s:
            assert s.scalars(select(UserSession)).all() == []  # the ended row is gone


def test_wrong_passwords_are_throttled_per_account_and_address_with_retry_after(app, client) -> None:  # type: ignore[no-untyped-def]
    for _ in range(10):
        assert login(client, "admin", "wrong-password").status_code == 401
    response = login(client, "admin")  # the right password, too late from the address that guessed
    assert response.status_code == 429 and int(response.headers["Retry-After"]) > 0
    assert "Too many failed logins for this name from your address" in response.get_data(as_text=True)
    assert login(client, "curator").status_code == 302  # another account from the same address still logs in


def test_wrong_passwords_from_one_address_slow_it_down_without_locking_it_out(app, client, runtime,  # type: ignore[no-untyped-def]
                                                                               monkeypatch) -> None:
    waits: list[float] = []
    monkeypatch.setattr("webapp.throttle.time.sleep", waits.append)
    with transaction(runtime.sessions) as s:
        for i in range(12):
            user_service.create_user(s, f"user{i}", Role.annotator, PASSWORD)
    for i in range(50):
        assert login(client, f"user{i % 12}", "wrong-password").status_code == 401
    assert waits == []
    assert login(client, "user0", "wrong-password").status_code == 401
    assert login(client, "curator").status_code == 302  # slowed down, not refused
    assert waits == [0.25, 0.5]


def test_bad_api_tokens_are_throttled_per_address(client, tokens) -> None:  # type: ignore[no-untyped-def]
    for _ in range(50):
        assert client.get("/api/v1/me", headers={"Authorization": "Bearer ist_guess"}).status_code == 401
    response = client.get("/api/v1/me", headers={"Authorization": "Bearer ist_guess"})
    assert response.status_code == 429 and int(response.headers["Retry-After"]) > 0
    assert "too many bad API tokens" in response.json["error"]
    # others' guesses from the same address (a proxy) never lock a right token out
    assert client.get("/api/v1/me", headers={"Authorization": f"Bearer {tokens['admin']}"}).status_code == 200


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def wrong_secret(token: str) -> str:
    """The same token id with a secret of the right shape that is not its own."""
    return token[:-43] + "x" * 43


def test_wrong_secrets_for_a_token_are_throttled_per_account(client, runtime, tokens) -> None:  # type: ignore[no-untyped-def]
    admin = tokens["admin"]
    assert re.fullmatch(r"ist_[0-9]+_[A-Za-z0-9_-]{43}", admin)
    with transaction(runtime.sessions) as s:
        second = user_service.issue_token(s, user_service.get_user(s, "admin"), "second")
    for _ in range(10):
        assert client.get("/api/v1/me", headers=bearer(wrong_secret(admin))).status_code == 401
    for token in (admin, second):  # past the account's limit, guesses at either of its tokens get 429
        response = client.get("/api/v1/me", headers=bearer(wrong_secret(token)))
        assert response.status_code == 429 and int(response.headers["Retry-After"]) > 0
        assert response.json["error"] == "too many bad API tokens; try again later"
    for token in (admin, second, tokens["curator"]):  # the right tokens are never locked out by a guesser
        assert client.get("/api/v1/me", headers=bearer(token)).status_code == 200


def test_a_new_tokens_bare_secret_is_no_token(client, tokens) -> None:  # type: ignore[no-untyped-def]
    secret = tokens["admin"].split("_", 2)[2]
    assert client.get("/api/v1/me", headers=bearer(secret)).status_code == 401
    assert client.get("/api/v1/me", headers=bearer("ist_" + secret)).status_code == 401


def test_old_format_tokens_work_and_count_per_address_only(client, runtime, tokens) -> None:  # type: ignore[no-untyped-def]
    old = "ist_" + secrets.token_urlsafe(32)
    with transaction(runtime.sessions) as s:
        s.add(ApiToken(user_id=user_service.get_user(s, "annotator").id, token_sha256=hashlib.sha256(old.encode()).hexdigest()))
    assert client.get("/api/v1/me", headers=bearer(old)).json["name"] == "annotator"
    for _ in range(12):  # wrong old-format tokens name no account: past the per-account limit, still fine
        assert client.get("/api/v1/me", headers=bearer(wrong_secret(old))).status_code == 401
    assert client.get("/api/v1/me", headers=bearer(old)).status_code == 200
    assert client.get("/api/v1/me", headers=bearer(tokens["admin"])).status_code == 200


def test_token_throttling_fails_open_while_its_counters_are_down(tmp_path: Path) -> None:
    from webapp.app import create_app

    settings = make_settings(tmp_path / "down", queue_url="redis://127.0.0.1:1/0")  # nothing listens on port 1
    migrate(settings.database_url)
    runtime = Runtime(settings)
    with transaction(runtime.sessions) as s:
        token = user_service.issue_token(s, user_service.create_user(s, "cu", "curator", PASSWORD))
    client = create_app(settings, runtime).test_client()
    for _ in range(12):
        assert client.get("/api/v1/me", headers=bearer(wrong_secret(token))).status_code == 401
    assert client.get("/api/v1/me", headers=bearer(token)).status_code == 200
    runtime.close()


def test_the_throttle_counts_across_processes_in_one_sqlite_file(runtime) -> None:  # type: ignore[no-untyped-def]
    from limits import parse
    from limits.strategies import FixedWindowRateLimiter

    from webapp.throttle import SqliteLimitStorage, storage_uri

    uri = storage_uri(runtime.settings)
    one, two = FixedWindowRateLimiter(SqliteLimitStorage(uri)), FixedWindowRateLimiter(SqliteLimitStorage(uri))
    item = parse("3 per minute")
    assert one.hit(item, "k") and two.hit(item, "k") and one.hit(item, "k")
    assert not two.hit(item, "k")  # the second "process" sees the first one's hits
    assert not one.test(item, "k") and one.test(item, "other")


def admin_post(client, path: str, **data: str):  # type: ignore[no-untyped-def]
    token = csrf_from(client.get("/admin/users").get_data(as_text=True))
    return client.post(path, data={"csrf_token": token, **data})


def test_admins_manage_accounts_from_the_users_page(app, client, runtime, tokens) -> None:  # type: ignore[no-untyped-def]
    login(client, "admin")
    uid = user_id(runtime, "curator")
    assert admin_post(client, f"/admin/users/{uid}/role", role="annotator").status_code == 303
    assert admin_post(client, f"/admin/users/{uid}/tokens/revoke").status_code == 303
    script = app.test_client()  # no session cookie: the token alone
    assert script.get("/api/v1/me", headers={"Authorization": f"Bearer {tokens['curator']}"}).status_code == 401
    assert admin_post(client, f"/admin/users/{uid}/password", password="a-new-password").status_code == 303
    assert login(app.test_client(), "curator", "a-new-password").status_code == 302
    assert admin_post(client, f"/admin/users/{uid}/active", active="0").status_code == 303
    assert login(app.test_client(), "curator", "a-new-password").status_code == 401
    assert admin_post(client, f"/admin/users/{uid}/active", active="1").status_code == 303
    response = admin_post(client, f"/admin/users/{uid}/password", password="short")
    assert response.status_code == 303 and response.location == "/admin/users"  # the error shows on the page
    page = client.get("/admin/users").get_data(as_text=True)
    assert "Nothing changed for curator: password must have at least 8 characters." in page
    assert "New password…" in page and "Revoke tokens" in page and "Deactivate…" in page
    assert client.post(f"/admin/users/{uid}/active", data={"active": "0"}).status_code == 400  # no CSRF token
    with runtime.sessions() as s:
        actions = [e.action for e in s.scalars(select(AuditEntry).where(AuditEntry.target_id == uid))]
        assert actions == ["user.role", "user.revoke_tokens", "user.password", "user.deactivate", "user.activate"]
        assert all(e.user_id == user_id(runtime, "admin") for e in s.scalars(select(AuditEntry)))
        assert s.get(User, uid).role == Role.annotator


def test_the_last_admin_cannot_be_removed(client, runtime) -> None:  # type: ignore[no-untyped-def]
    login(client, "admin")
    uid = user_id(runtime, "admin")
    response = admin_post(client, f"/admin/users/{uid}/active", active="0")
    assert response.status_code == 303 and response.location == "/admin/users"
    assert "admin is the last active admin" in client.get("/admin/users").get_data(as_text=True)
    assert admin_post(client, f"/admin/users/{uid}/role", role="curator").status_code == 303
    with runtime.sessions() as s:
        admin = s.get(User, uid)
        assert admin.active and admin.role == Role.admin
    with transaction(runtime.sessions) as s:
        user_service.set_role(s, None, user_service.get_user(s, "curator"), Role.admin)
    assert admin_post(client, f"/admin/users/{uid}/role", role="curator").status_code == 303
    with runtime.sessions() as s:
        assert s.get(User, uid).role == Role.curator


def test_the_cli_manages_accounts(settings, runtime, tokens) -> None:  # type: ignore[no-untyped-def]
    runner = CliRunner()
    base = ["--data-dir", str(settings.home), "users"]
    assert runner.invoke(cli, [*base, "role", "annotator", "curator"]).exit_code == 0
    result = runner.invoke(cli, [*base, "password", "annotator", "--password-stdin"], input="brand-new-pass\n")
    assert result.exit_code == 0, result.output
    assert "1 API token revoked for good" in result.output
    assert "revoked 0 token(s)" in runner.invoke(cli, [*base, "revoke-tokens", "annotator"]).output
    assert runner.invoke(cli, [*base, "deactivate", "annotator"]).exit_code == 0
    assert "disabled" in runner.invoke(cli, [*base, "list"]).output
    assert runner.invoke(cli, [*base, "reactivate", "annotator"]).exit_code == 0
    result = runner.invoke(cli, [*base, "deactivate", "admin"])
    assert result.exit_code != 0 and "last active admin" in result.output
    with runtime.sessions() as s:
        user = user_service.get_user(s, "annotator")
        assert user.role == Role.curator and user.active
        assert user_service.authenticate(s, "annotator", "brand-new-pass") is not None
        assert len(s.scalars(select(AuditEntry)).all()) == 5


def test_user_names_are_whole_matches_and_unique_ignoring_case(client, tokens) -> None:  # type: ignore[no-untyped-def]
    auth = {"Authorization": f"Bearer {tokens['admin']}"}
    for name, status in (("admin\n", 400), ("Admin", 409), ("new.user", 201), ("NEW.USER", 409)):
        response = client.post("/api/v1/users", json={"name": name, "role": "admin", "password": PASSWORD}, headers=auth)
        assert response.status_code == status, (name, response.json)
