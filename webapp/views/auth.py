"""Login, logout and the health check: the pages anyone may reach."""

from __future__ import annotations

from urllib.parse import urlsplit

from flask import Blueprint, current_app, flash, g, redirect, render_template, request, send_from_directory, url_for
from flask.typing import ResponseReturnValue
from flask_login import login_user, logout_user
from sqlalchemy import select

from dataset.models import Role
from dataset.services import users as user_service
from webapp.auth import SessionUser, public, requires
from webapp.forms import LoginForm

bp = Blueprint("auth", __name__)


@bp.get("/healthz")
@public
def healthz() -> ResponseReturnValue:
    g.db.execute(select(1))
    return {"status": "ok"}


@bp.get("/favicon.ico")
@public
def favicon() -> ResponseReturnValue:
    """Browsers ask for it before reading the page's icon link; the same SVG answers."""
    return send_from_directory(current_app.static_folder or "static", "favicon.svg", mimetype="image/svg+xml",
                               max_age=86400)


@bp.route("/login", methods=["GET", "POST"])
@public
def login() -> ResponseReturnValue:
    form = LoginForm()
    if form.validate_on_submit():
        user = user_service.authenticate(g.db, form.name.data, form.password.data)
        if user is not None:
            login_user(SessionUser(user))
            return redirect(_safe_next(request.args.get("next")))
        flash("Wrong user name or password.", "error")
        return render_template("login.html", form=form), 401
    return render_template("login.html", form=form)


def _safe_next(target: str | None) -> str:
    """Only same-site paths, so the login page cannot be used to redirect elsewhere."""
    # Browsers read "\" as "/", so "/\\evil.example" would leave the site too.
    if target and target.startswith("/") and target[1:2] not in ("/", "\\") and target.isprintable() \
            and "\\" not in target:
        parts = urlsplit(target)
        if not parts.scheme and not parts.netloc:
            return target
    return url_for("dashboard.dashboard")


@bp.post("/logout")
@requires(Role.annotator)
def logout() -> ResponseReturnValue:
    logout_user()
    flash("Logged out.", "info")
    return redirect(url_for("auth.login"))
