"""User administration: admins only."""

from __future__ import annotations

from flask import Blueprint, flash, g, redirect, render_template, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user
from sqlalchemy import select

from dataset.models import Role, User
from dataset.services import users as user_service
from dataset.services.errors import ServiceError
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


def _users_page(form: CreateUserForm) -> str:
    rows = g.db.scalars(select(User).order_by(User.name)).all()
    return render_template("users.html", users=rows, form=form, me=current_user)
