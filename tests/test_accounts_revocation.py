"""What a password reset, a deactivation and a login leave working: a reset or a deactivation revokes
the user's API tokens for good (reactivation brings none back), the Users page and the CLI say so,
and the CSRF token issued before a login is void after it."""

from __future__ import annotations

import re

import pytest
from click.testing import CliRunner
from sqlalchemy import select

from dataset.db import transaction
from dataset.services import users as user_service
from dataset.services.errors import Conflict
from dataset.tables import ApiToken
from tests.conftest import PASSWORD, csrf_from, login
from webapp.cli import main as cli


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def admin_post(client, path: str, **data: str):  # type: ignore[no-untyped-def]
    token = csrf_from(client.get("/admin/users").get_data(as_text=True))
    return client.post(path, data={"csrf_token": token, **data})


def user_id(runtime, name: str) -> int:  # type: ignore[no-untyped-def]
    with runtime.sessions() as s:
        return user_service.get_user(s, name).id


def test_a_password_reset_on_the_users_page_revokes_the_users_tokens(app, client, runtime, tokens) -> None:  # type: ignore[no-untyped-def]
    script = app.test_client()
    assert script.get("/api/v1/me", headers=bearer(tokens["curator"])).status_code == 200
    login(client, "admin")
    response = admin_post(client, f"/admin/users/{user_id(runtime, 'curator')}/password", password="a-new-password")
    assert response.status_code == 303 and response.location == "/admin/users"
    page = client.get("/admin/users").get_data(as_text=True)
    assert "New password set for curator: sessions ended, 1 API token revoked for good." in page
    assert script.get("/api/v1/me", headers=bearer(tokens["curator"])).status_code == 401
    assert script.get("/api/v1/me", headers=bearer(tokens["annotator"])).status_code == 200  # others' stay


def test_deactivation_revokes_tokens_and_reactivation_brings_none_back(app, client, runtime, tokens) -> None:  # type: ignore[no-untyped-def]
    script = app.test_client()
    uid = user_id(runtime, "curator")
    login(client, "admin")
    policy = " ".join(re.search(r'id="token-policy">(.*?)</p>', client.get("/admin/users").get_data(as_text=True),
                                re.S)[1].split())  # said on the page, before acting
    assert "a deactivation ends the user's sessions and revokes their API tokens for good" in policy
    assert "Reactivating lets them log in again but brings no token back" in policy
    assert admin_post(client, f"/admin/users/{uid}/active", active="0").status_code == 303
    page = client.get("/admin/users").get_data(as_text=True)
    assert "Deactivated curator: sessions ended, 1 API token revoked for good." in page
    with transaction(runtime.sessions) as s, pytest.raises(Conflict, match="reactivate them first"):
        user_service.issue_token(s, user_service.get_user(s, "curator"))  # no token slipped in meanwhile
    assert admin_post(client, f"/admin/users/{uid}/active", active="1").status_code == 303
    assert "no API token came back" in client.get("/admin/users").get_data(as_text=True)
    assert script.get("/api/v1/me", headers=bearer(tokens["curator"])).status_code == 401
    assert login(app.test_client(), "curator").status_code == 302  # the password works again
    with transaction(runtime.sessions) as s:
        fresh = user_service.issue_token(s, user_service.get_user(s, "curator"))
    assert script.get("/api/v1/me", headers=bearer(fresh)).json["name"] == "curator"


def test_the_cli_says_what_happened_to_the_tokens(app, settings, runtime, tokens) -> None:  # type: ignore[no-untyped-def]
    runner = CliRunner()
    base = ["--data-dir", str(settings.home), "users"]
    script = app.test_client()
    result = runner.invoke(cli, [*base, "password", "annotator", "--password-stdin"], input="brand-new-pass\n")
    assert result.exit_code == 0, result.output
    assert result.output.strip() == "new password set for annotator: sessions ended, 1 API token revoked for good"
    assert script.get("/api/v1/me", headers=bearer(tokens["annotator"])).status_code == 401

    with transaction(runtime.sessions) as s:
        second = [user_service.issue_token(s, user_service.get_user(s, "curator")) for _ in range(2)]
    result = runner.invoke(cli, [*base, "deactivate", "curator"])
    assert result.exit_code == 0, result.output
    assert "deactivated curator: sessions ended, 3 API tokens revoked for good" in result.output
    assert "reactivating does not bring them back" in result.output
    result = runner.invoke(cli, [*base, "reactivate", "curator"])
    assert result.exit_code == 0 and "no API token came back" in result.output
    assert "illusion-studio users token curator" in result.output
    for token in [tokens["curator"], *second]:
        assert script.get("/api/v1/me", headers=bearer(token)).status_code == 401
    with runtime.sessions() as s:
        assert s.scalars(select(ApiToken).where(ApiToken.user_id == user_id(runtime, "curator"))).all() == []
    result = runner.invoke(cli, [*base, "deactivate", "curator"])
    assert result.exit_code == 0 and "0 API tokens revoked" in result.output
    result = runner.invoke(cli, [*base, "token", "curator"])
    assert result.exit_code != 0 and "curator is deactivated; reactivate them first" in result.output


def test_the_csrf_token_issued_before_login_is_void_after_it(client) -> None:  # type: ignore[no-untyped-def]
    before = csrf_from(client.get("/login").get_data(as_text=True))
    response = client.post("/login", data={"name": "admin", "password": PASSWORD, "csrf_token": before})
    assert response.status_code == 302
    body = {"name": "newbie", "role": "annotator", "password": "long-enough"}
    refused = client.post("/api/v1/users", json=body, headers={"X-CSRFToken": before})
    assert refused.status_code == 400 and "CSRF" in refused.json["error"]
    after = csrf_from(client.get("/admin/users").get_data(as_text=True))
    assert client.post("/api/v1/users", json=body, headers={"X-CSRFToken": after}).status_code == 201
    assert client.post("/api/v1/users", json={**body, "name": "other"},
                       headers={"X-CSRFToken": before}).status_code == 400  # still void
