"""Login, logout and the health check: the pages anyone may reach."""

from __future__ import annotations

from datetime import datetime, timedelta
from urllib.parse import urlsplit

from flask import Blueprint, current_app, flash, g, redirect, render_template, request, send_from_directory, session, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user
from markupsafe import escape
from sqlalchemy import select

from core.wording import plural
from dataset.services import users as user_service
from dataset.services.session_reasons import why_session_ended
from dataset.tables import Role, utcnow
from webapp.auth import public, requires, sign_in, sign_out
from webapp.forms import LoginForm
from webapp.runtime import runtime
from webapp.throttle import LoginAttempt, Refusal, set_device_cookie

bp = Blueprint("auth", __name__)
# The cookie's note of when this browser logged in: once its session has ended, why it ended is told
# from what happened to the account since (the session's own row is gone by then).
SIGNED_IN_AT = "signed_in_at"
REFUSED_PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>Log in · Illusion Studio</title><link rel="stylesheet" href="{css}"></head>
<body><main><section class="card narrow"><h1>Log in</h1><p class="flash error" role="alert">{message}</p>
<p><a href="{login}">Back to the login page</a></p></section></main></body></html>
"""


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
    if request.method == "GET" and current_user.is_authenticated:
        # Logged in again in another tab: "log in again" links from ended sessions go straight back.
        return redirect(_safe_next(request.args.get("next")))
    form = LoginForm()
    if form.validate_on_submit():
        settings = runtime().settings
        attempt = LoginAttempt.start(settings, form.name.data)
        if (refusal := attempt.refusal(settings)) is not None:
            return _refused(refusal)
        user = user_service.authenticate(g.db, form.name.data, form.password.data)
        if user is not None:
            attempt.succeeded()
            sign_in(user)
            session[SIGNED_IN_AT] = utcnow().isoformat()
            response = redirect(_safe_next(request.args.get("next")))
            set_device_cookie(response, settings, user.name, path=url_for("auth.login"))
            return response
        attempt.failed()
        flash("Wrong user name or password.", "error")
        return render_template("login.html", form=form), 401
    return render_template("login.html", form=form, ended=ended_reason())


def _refused(refusal: Refusal) -> ResponseReturnValue:
    """429 and a one-paragraph page, no template: a flood's refused logins come by the hundred a
    second, and rendering the login form was a third of the cost of each."""
    if refusal.busy:
        message = f"Many logins are being slowed down just now: try again in {plural(refusal.retry_after, 'second')}."
    else:
        minutes = plural(-(-refusal.retry_after // 60), "minute")
        message = f"Too many failed logins for this name from your address: try again in {minutes}."
    page = REFUSED_PAGE.format(css=escape(url_for("static", filename="css/app.css")), message=escape(message),
                               login=escape(request.full_path if request.query_string else request.path))
    return page, 429, {"Retry-After": str(refusal.retry_after)}


@bp.get("/login/ended")
@public
def session_ended() -> ResponseReturnValue:
    """``{"reason", "then"}``: why this browser's session ended and what to do (nulls when it had none or
    the server cannot tell); an open tab asks when a request of its own was refused (static/js/session_banner.js)."""
    reason, then = ended_reason() or (None, None)
    return {"reason": reason, "then": then}


def ended_reason() -> tuple[str, str] | None:
    """Why this browser's session ended and what to do: its cookie still names the user it was
    logged in as and when, but the session is gone."""
    user_id, since = session.get("_user_id"), session.get(SIGNED_IN_AT)
    if current_user.is_authenticated or not user_id or not since:
        return None
    try:
        user, signed_in_at = int(user_id), datetime.fromisoformat(since)
    except (TypeError, ValueError):
        return None
    lifetime = timedelta(hours=runtime().settings.session_lifetime_hours)
    return why_session_ended(g.db, user, signed_in_at, lifetime=lifetime)


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
    sign_out()
    flash("Logged out.", "info")
    return redirect(url_for("auth.login"))
