"""User administration: admins only. Every change is audited and applies on the user's next request.

Each change answers with a redirect back to the Users page and a flash saying what happened (what
went wrong included), so the browser never stays on a POST address.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from flask import Blueprint, flash, g, redirect, render_template, request, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user
from sqlalchemy import select

from core.wording import plural
from dataset.services import users as user_service
from dataset.services.errors import ServiceError
from dataset.tables import Role, User
from webapp.api.blueprint import get_or_404
from webapp.auth import requires
from webapp.forms import CreateUserForm

bp = Blueprint("admin", __name__)
T = TypeVar("T")


@bp.get("/admin/users")
@requires(Role.admin)
def users() -> ResponseReturnValue:
    return _users_page(CreateUserForm())


@bp.post("/admin/users")
@requires(Role.admin)
def create_user() -> ResponseReturnValue:
    form = CreateUserForm()
    if not form.validate():
        return _users_page(form), 400
    try:
        user_service.create_user(g.db, form.name.data, form.role.data, form.password.data)
    except ServiceError as exc:
        flash(str(exc), "error")
        return _users_page(form), exc.status
    g.db.commit()
    flash(f"Created {form.role.data} {form.name.data}.", "info")
    return redirect(url_for("admin.users"))


@bp.post("/admin/users/<int:user_id>/active")
@requires(Role.admin)
def set_active(user_id: int) -> ResponseReturnValue:
    if request.form.get("active") == "1":
        return _change(user_id, lambda u: user_service.set_active(g.db, current_user.id, u, True),
                       lambda u, _: f"Reactivated {u.name}: they can log in again; no API token came back.")
    return _change(user_id, lambda u: user_service.set_active(g.db, current_user.id, u, False),
                   lambda u, n: f"Deactivated {u.name}: sessions ended, {user_service.revoked_words(n)}.")


@bp.post("/admin/users/<int:user_id>/role")
@requires(Role.admin)
def set_role(user_id: int) -> ResponseReturnValue:
    role = request.form.get("role", "")
    return _change(user_id, lambda u: user_service.set_role(g.db, current_user.id, u, role),
                   lambda u, _: f"{u.name} is now {role}.")


@bp.post("/admin/users/<int:user_id>/password")
@requires(Role.admin)
def reset_password(user_id: int) -> ResponseReturnValue:
    password = request.form.get("password", "")
    return _change(user_id, lambda u: user_service.reset_password(g.db, current_user.id, u, password),
                   lambda u, n: f"New password set for {u.name}: sessions ended, {user_service.revoked_words(n)}.")


@bp.post("/admin/users/<int:user_id>/tokens/revoke")
@requires(Role.admin)
def revoke_tokens(user_id: int) -> ResponseReturnValue:
    return _change(user_id, lambda u: user_service.revoke_tokens(g.db, current_user.id, u),
                   lambda u, n: f"Revoked {plural(n, 'API token')} of {u.name}.")


def _change(user_id: int, apply: Callable[[User], T], done: Callable[[User, T], str]) -> ResponseReturnValue:
    """Apply one change to user ``user_id``; back to the Users page with what happened, or why not."""
    user = get_or_404(User, user_id, "user")
    name = user.name
    try:
        result = apply(user)
    except ServiceError as exc:
        g.db.rollback()
        flash(f"Nothing changed for {name}: {str(exc).rstrip('.')}.", "error")
    else:
        g.db.commit()
        flash(done(user, result), "info")
    return redirect(url_for("admin.users"), 303)


def _users_page(form: CreateUserForm) -> str:
    rows = g.db.scalars(select(User).order_by(User.name)).all()
    return render_template("users.html", users=rows, form=form, me=current_user, roles=list(Role),
                           min_password=user_service.MIN_PASSWORD, max_password=user_service.MAX_PASSWORD)
