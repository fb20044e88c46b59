"""Who may do what: sessions and bearer tokens, roles declared on every view, CSRF.

Every view declares the least role it needs with :func:`requires` (or :func:`public`). One
``before_request`` hook enforces it for the whole app, so a view that forgets to declare
anything is refused rather than left open.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from flask import Flask, abort, g, jsonify, redirect, request, url_for
from flask_login import AnonymousUserMixin, LoginManager, UserMixin, current_user
from flask_wtf.csrf import CSRFProtect

from dataset.models import Role, User
from dataset.services import users as user_service

F = TypeVar("F", bound=Callable[..., Any])
PUBLIC = "public"
ROLE_ATTR = "required_role"

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
        user = g.db.get(User, int(user_id)) if user_id.isdigit() else None
        return SessionUser(user) if user is not None and user.active else None

    @login_manager.request_loader
    def load_from_token(req: Any) -> SessionUser | None:
        scheme, _, token = req.headers.get("Authorization", "").partition(" ")
        if scheme.lower() != "bearer" or not token:
            return None
        user = user_service.user_for_token(g.db, token.strip())
        if user is None:
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
        if required != PUBLIC:
            if not current_user.is_authenticated:
                if is_api_request():
                    return json_error(401, "authentication required: log in or send 'Authorization: Bearer <token>'")
                return redirect(url_for("auth.login", next=request.full_path.rstrip("?")))
            if not current_user.allows(required):
                abort(403, f"needs the {required.value} role")
        if request.method not in ("GET", "HEAD", "OPTIONS") and not getattr(current_user, "via_token", False):
            csrf.protect()
        return None
