"""The Users page in a real browser at 1366x768: one line per user, Deactivate in red and only after a
confirmation, a new password typed in a dialog, errors shown on the Users page (never the POST
address), and `?` explaining what each action does to sessions and API tokens."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from dataset.db import migrate, transaction
from dataset.services import users as user_service
from dataset.tables import Role
from tests.browser import login, page_with_errors, serving
from tests.conftest import PASSWORD, make_settings
from webapp.runtime import Runtime

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A workspace with one user per role (named after it), each with an API token; its server."""
    settings = make_settings(tmp_path_factory.mktemp("users") / "ws")
    migrate(settings.database_url)
    rt = Runtime(settings)
    with transaction(rt.sessions) as s:
        for role in Role:
            user_service.issue_token(s, user_service.create_user(s, role.value, role, PASSWORD))
    rt.close()
    with serving(settings.home) as url:
        yield url


def test_admin_deactivates_after_a_confirmation_and_errors_stay_on_the_page(browser, server: str,  # type: ignore[no-untyped-def]
                                                                            tmp_path: Path) -> None:
    from playwright.sync_api import expect

    url = server
    page, errors = page_with_errors(browser)
    login(page, url, "admin", PASSWORD)
    page.click("[data-nav=users]")
    page.wait_for_url(f"{url}/admin/users")
    rows = page.locator("table.users tbody tr")
    expect(rows).to_have_count(3)
    heights = rows.evaluate_all("rows => rows.map(r => r.getBoundingClientRect().height)")
    assert max(heights) < 50, heights  # one line per user
    assert page.evaluate("document.documentElement.scrollWidth") <= 1366
    page.screenshot(path=str(tmp_path / "users.png"), full_page=True)

    curator = page.locator("tr[data-user=curator]")
    deactivate = curator.get_by_role("button", name="Deactivate…")
    ordinary = curator.get_by_role("button", name="Revoke tokens")
    assert deactivate.evaluate("b => getComputedStyle(b).color") != ordinary.evaluate("b => getComputedStyle(b).color")

    dialog = page.locator("#confirm-dialog")
    deactivate.click()  # asks first; Cancel changes nothing
    expect(dialog).to_be_visible()
    expect(dialog).to_contain_text("Deactivate curator?")
    expect(dialog).to_contain_text("their API token is revoked for good")
    expect(dialog).to_contain_text("Reactivating lets them log in again but brings no token back")
    page.screenshot(path=str(tmp_path / "confirm.png"))
    page.keyboard.press("Escape")
    expect(dialog).to_be_hidden()
    expect(curator).to_have_attribute("data-active", "true")

    deactivate.click()
    dialog.get_by_role("button", name="Deactivate").click()
    page.wait_for_url(f"{url}/admin/users")
    expect(page.locator(".flash.info")).to_have_text("Deactivated curator: sessions ended, 1 API token revoked for good.")
    expect(curator).to_have_attribute("data-active", "false")
    expect(curator.locator("td.tokens")).to_have_text("0")
    expect(curator.get_by_role("button", name="Reactivate")).to_be_visible()

    # An error (the last active admin) comes back to the Users page with the reason, not to the POST address.
    page.locator("tr[data-user=admin]").get_by_role("button", name="Deactivate…").click()
    dialog.get_by_role("button", name="Deactivate").click()
    page.wait_for_load_state()
    assert page.url == f"{url}/admin/users"
    expect(page.locator(".flash.error")).to_contain_text("admin is the last active admin")
    expect(page.locator("tr[data-user=admin]")).to_have_attribute("data-active", "true")

    # A new password is typed in a dialog that says what happens to the tokens.
    page.locator("tr[data-user=annotator]").get_by_role("button", name="New password…").click()
    password = page.locator("#password-dialog")
    expect(password).to_contain_text("New password for annotator")
    expect(password).to_contain_text("their API token is revoked for good")
    password.locator("input[name=password]").fill("another-long-password")
    password.get_by_role("button", name="Set password").click()
    page.wait_for_url(f"{url}/admin/users")
    expect(page.locator(".flash.info")).to_have_text(
        "New password set for annotator: sessions ended, 1 API token revoked for good.")

    page.keyboard.press("?")
    help_dialog = page.locator("#keys-help")
    expect(help_dialog).to_be_visible()
    expect(help_dialog).to_contain_text("revokes their API tokens for good")
    page.keyboard.press("Escape")
    page.locator("[data-help]").click()
    expect(help_dialog).to_be_visible()
    assert errors == []
    page.close()
