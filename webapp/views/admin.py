"""User administration: admins only. Every change is audited and applies on the user's next request."""

from __future__ import annotations

from collections.abc import Callable

from flask import Blueprint, flash, g, redirect, render_template, request, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user
from sqlalchemy import select

from dataset.models import Role, User
from dataset.services import users as user_service
from dataset.services.errors import ServiceError
from webapp.api.blueprint import get_or_404
from webapp.auth import requires
from webapp.forms import CreateUserForm

bp = Blueprint("admin", __name__)


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
    active = request.form.get("active") == "1"
    return _change(user_id, lambda u: user_service.set_active(g.db, current_user.id, u, active),
                   "Reactivated {name}." if active else "Deactivated {name}; their sessions ended.")


@bp.post("/admin/users/<int:user_id>/role")
@requires(Role.admin)
def set_role(user_id: int) -> ResponseReturnValue:
    role = request.form.get("role", "")
    return _change(user_id, lambda u: user_service.set_role(g.db, current_user.id, u, role),
                   "{name} is now " + role + ".")


@bp.post("/admin/users/<int:user_id>/password")
@requires(Role.admin)
def reset_password(user_id: int) -> ResponseReturnValue:
    password = request.form.get("password", "")
    return _change(user_id, lambda u: user_service.reset_password(g.db, current_user.id, u, password),
                   "New password set for {name}; their sessions ended.")


@bp.post("/admin/users/<int:user_id>/tokens/revoke")
@requires(Role.admin)
def revoke_tokens(user_id: int) -> ResponseReturnValue:
    return _change(user_id, lambda u: user_service.revoke_tokens(g.db, current_user.id, u),
                   "Revoked the API tokens of {name}.")


def _change(user_id: int, apply: Callable[[User], object], done: str) -> ResponseReturnValue:
    user = get_or_404(User, user_id, "user")
    try:
        apply(user)
    except ServiceError as exc:
        g.db.rollback()
        flash(str(exc), "error")
        return _users_page(CreateUserForm()), exc.status
    g.db.commit()
    flash(done.format(name=user.name), "info")
    return redirect(url_for("admin.users"))


def _users_page(form: CreateUserForm) -> str:
    rows = g.db.scalars(select(User).order_by(User.name)).all()
    return render_template("users.html", users=rows, form=form, me=current_user, roles=list(Role))
