"""Who may do what: sessions and bearer tokens, roles declared on every view, CSRF.

Every view declares the least role it needs with :func:`requires` (or :func:`public`). One
``before_request`` hook enforces it for the whole app, so a view that forgets to declare
anything is refused rather than left open.
"""

from __future__ import annotations

from collections.abc import Callable
from datetime import timedelta
from typing import Any, TypeVar

from flask import Flask, abort, current_app, g, jsonify, redirect, request, session, url_for
from flask_login import AnonymousUserMixin, LoginManager, UserMixin, current_user, login_user, logout_user
from flask_wtf.csrf import CSRFProtect
from werkzeug.datastructures import WWWAuthenticate
from werkzeug.exceptions import HTTPException, TooManyRequests, Unauthorized

from dataset.services import sessions as session_service
from dataset.services import users as user_service
from dataset.tables import Role, User
from webapp import throttle
from webapp.runtime import runtime

F = TypeVar("F", bound=Callable[..., Any])
PUBLIC = "public"
ROLE_ATTR = "required_role"
SESSION_ID = "sid"  # the cookie's key holding the server-side session's id
SESSION_ENDED = "Your session ended — log in again."
BAD_TOKEN = ("this API token is not valid: mistyped, revoked, or its user was deactivated or given a new password "
             "(both revoke tokens for good); an admin issues a new one with 'illusion-studio users token NAME'")
TOKEN_REFUSED = "token_refused"  # g's key for why this request's bearer token was refused

login_manager = LoginManager()
csrf = CSRFProtect()


class SessionUser(UserMixin):
    """The logged-in user as Flask-Login sees it: a detached snapshot, never a live ORM row."""

    def __init__(self, user: User, via_token: bool = False) -> None:
        self.id, self.name, self.role, self.via_token = user.id, user.name, user.role, via_token

    def get_id(self) -> str:
        return str(self.id)

    def allows(self, role: Role | str) -> bool:
        return self.role.allows(Role(role))


class Anonymous(AnonymousUserMixin):
    role = None

    def allows(self, role: Role | str) -> bool:
        return False


def requires(role: Role) -> Callable[[F], F]:
    """Declare that a view needs at least ``role``."""

    def mark(view: F) -> F:
        setattr(view, ROLE_ATTR, role)
        return view

    return mark


def public(view: F) -> F:
    """Declare that a view is open to everyone (login page, health check)."""
    setattr(view, ROLE_ATTR, PUBLIC)
    return view


def is_api_request() -> bool:
    return request.path.startswith("/api/")


def json_error(status: int, message: str) -> Any:
    response = jsonify(error=message, status=status)
    response.status_code = status
    return response


def _unauthenticated_message() -> str:
    """Why an API call is refused, in the words its reader needs.

    A browser carries the app's cookie and no token: its session ended (logged out elsewhere,
    idle, too old), and the page shows the message. Scripts get the how-to they always got.
    """
    if "Authorization" not in request.headers and current_app.config["SESSION_COOKIE_NAME"] in request.cookies:
        return SESSION_ENDED
    return "authentication required: log in or send 'Authorization: Bearer <token>'"


def sign_in(user: User) -> None:
    """Start a server-side session for ``user`` and put its id in the cookie."""
    # Nothing issued before the login outlives it: the CSRF token of the login page (a planted
    # one included) is void, and the next page gets a new one; a session this browser had ends on
    # the server too, so a copy of its old cookie is worthless.
    if old := session.get(SESSION_ID):
        session_service.end_session(g.db, old)
    session.clear()
    g.pop(current_app.config.get("WTF_CSRF_FIELD_NAME", "csrf_token"), None)
    # A fresh random id per login: an id seen before (a copied cookie) never comes back to life.
    session[SESSION_ID] = session_service.start_session(g.db, user)
    g.db.commit()
    login_user(SessionUser(user))


def sign_out() -> None:
    """End this browser's session on the server too, so a copy of the cookie is worthless."""
    if sid := session.get(SESSION_ID):
        session_service.end_session(g.db, sid)
        g.db.commit()
    logout_user()
    session.pop(SESSION_ID, None)


def init_auth(app: Flask) -> None:
    login_manager.init_app(app)
    login_manager.anonymous_user = Anonymous
    # "strong" would drop bearer-token requests whose cookie jar holds a stale session.
    login_manager.session_protection = "basic"
    # The API checks CSRF itself, after authorisation: token clients are exempt (see _authorise).
    app.config["WTF_CSRF_CHECK_DEFAULT"] = False
    csrf.init_app(app)

    @login_manager.user_loader
    def load_user(user_id: str) -> SessionUser | None:
        sid = session.get(SESSION_ID)
        settings = runtime().settings
        user = session_service.user_for_session(
            g.db, sid, idle=timedelta(minutes=settings.session_idle_minutes),
            lifetime=timedelta(hours=settings.session_lifetime_hours)) if isinstance(sid, str) else None
        if g.db.dirty or g.db.deleted:
            g.db.commit()  # the session's last-seen time, or its end
        if user is None or str(user.id) != user_id:
            session.pop(SESSION_ID, None)
            return None
        return SessionUser(user)

    @login_manager.request_loader
    def load_from_token(req: Any) -> SessionUser | None:
        # Never raises: a loader that raised would run again for the error page (its top bar asks
        # who is logged in) and raise there too. _authorise answers the refusal instead.
        scheme, _, token = req.headers.get("Authorization", "").partition(" ")
        if scheme.lower() != "bearer" or not token:
            return None
        settings, token = runtime().settings, token.strip()
        user = user_service.user_for_token(g.db, token)
        if user is None:
            # The right token always passes: only bad ones are counted, and past the address's or
            # the named account's limit they get 429, so neither a stranger who knows a token's
            # (public) id nor others' guesses from the same proxy lock a script out.
            wait = throttle.bad_token(settings, user_service.token_account(g.db, token))
            refusal: HTTPException = TooManyRequests(throttle.TOKEN_LIMIT_MESSAGE, retry_after=wait) if wait \
                else Unauthorized(BAD_TOKEN, www_authenticate=WWWAuthenticate("bearer", {"error": "invalid_token"}))
            setattr(g, TOKEN_REFUSED, refusal)
            return None
        if g.db.dirty:
            g.db.commit()  # keep the token's last-used time
        return SessionUser(user, via_token=True)

    @app.before_request
    def _authorise() -> Any:
        view = app.view_functions.get(request.endpoint or "")
        if view is None or request.endpoint == "static":
            return None  # 404 / 405 / static files: nothing to protect
        required = getattr(view, ROLE_ATTR, None)
        if required is None:
            abort(403, "this route declares no role")
        if "Authorization" in request.headers:
            _ = current_user.is_authenticated  # run the token loader now, before the view
            refused: HTTPException | None = g.get(TOKEN_REFUSED)
            if refused is not None:  # a bad token on any route, a page or /login included: 401 or 429
                raise refused
        if required != PUBLIC:
            if not current_user.is_authenticated:
                if is_api_request():
                    return json_error(401, _unauthenticated_message())
                return redirect(url_for("auth.login", next=request.full_path.rstrip("?")))
            if not current_user.allows(required):
                abort(403, f"needs the {required.value} role")
        # The first read of a body (the form's token): after the body limit (webapp.bodies) and the role checks above.
        if request.method not in ("GET", "HEAD", "OPTIONS") and not getattr(current_user, "via_token", False):
            csrf.protect()
        return None
