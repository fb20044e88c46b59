"""The Flask app factory."""

from __future__ import annotations

import secrets
from pathlib import Path
from typing import Any

from flask import Flask, abort, g, jsonify, make_response, render_template, request
from flask_wtf.csrf import CSRFError
from werkzeug.exceptions import HTTPException
from werkzeug.routing import IntegerConverter, Map

from core.atomic import atomic_write_bytes
from core.wording import plural
from dataset.services.errors import ServiceError
from dataset.services.media_gc import clean_incoming
from dataset.services.validate import DB_INT_MAX
from dataset.settings import Settings
from webapp.auth import init_auth, is_api_request, json_error
from webapp.bodies import init_body_limits
from webapp.headers import init_headers
from webapp.json_provider import FiniteJSONProvider
from webapp.redact import init_redaction
from webapp.runtime import Runtime
from webapp.throttle import DEFAULT_SERVER_THREADS, init_throttle


class AsciiIntegerConverter(IntegerConverter):
    """``<int:…>`` in URLs: ASCII digits only (werkzeug's ``\\d`` also takes ``２`` or ``١`` as 2 and 1)."""

    regex = r"[0-9]+"


class DatabaseInt(AsciiIntegerConverter):
    """``<int:…>``: ASCII digits, limited to the integers the database's INTEGER columns store."""

    def __init__(self, url_map: Map, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("max", DB_INT_MAX)
        super().__init__(url_map, *args, **kwargs)


STALE_UPLOAD_S = 600.0


def static_dir() -> Path:
    """The pages' scripts, styles and icons: ``webapp/static`` in an installed wheel (setup.py copies
    it there), else the top-level ``static/`` of the checkout this package runs from."""
    package = Path(__file__).resolve().parent
    packaged = package / "static"
    return packaged if packaged.is_dir() else package.parent / "static"


def create_app(settings: Settings, runtime: Runtime | None = None, *, threads: int = DEFAULT_SERVER_THREADS) -> Flask:
    """Build the app for ``settings``, served by ``threads`` worker threads; tests may pass a shared ``runtime``."""
    rt = runtime or Runtime(settings)
    # Part files of uploads a killed server left behind (a live upload keeps writing its part).
    clean_incoming(rt.media, older_than_s=STALE_UPLOAD_S)
    app = Flask(__name__, static_folder=str(static_dir()), static_url_path="/static")
    app.config.update(
        SECRET_KEY=settings.secret_key or _stored_secret(settings.home),
        SESSION_COOKIE_HTTPONLY=True,
        SESSION_COOKIE_SAMESITE="Lax",
        SESSION_COOKIE_SECURE=settings.https,
    )
    app.json = FiniteJSONProvider(app)
    app.json.sort_keys = False  # type: ignore[attr-defined]
    # Before any route is added: ids beyond what the database stores are a 404, not a crash.
    app.url_map.converters["int"] = DatabaseInt
    app.extensions["runtime"] = rt
    app.add_template_filter(plural)  # {{ n|plural('frame') }}: "1 frame", "2 frames"

    @app.before_request
    def _open_session() -> None:
        g.db = rt.sessions()

    @app.before_request
    def _refuse_null_bytes() -> None:
        # A NUL reaching the file system is a ValueError ("embedded null byte") in any route that
        # opens a file by a name from the URL: refuse it here, once, for every route.
        if "\x00" in request.path or any("\x00" in key or any("\x00" in v for v in values)
                                         for key, values in request.args.lists()):
            abort(400, "the URL contains a null byte (%00): no path or name holds one")

    init_body_limits(app, settings)  # before any hook that may read a body: the limits, auth, CSRF

    @app.teardown_request
    def _close_session(_exc: BaseException | None) -> None:
        db = g.pop("db", None)
        if db is not None:
            db.close()

    init_throttle(app, settings, threads)
    init_headers(app, settings)
    init_auth(app)

    from webapp.api import api
    from webapp.views import BLUEPRINTS

    for blueprint in BLUEPRINTS:
        app.register_blueprint(blueprint)
    app.register_blueprint(api, url_prefix="/api/v1")
    init_redaction(app, settings)
    _register_errors(app)
    return app


def _stored_secret(home: Path) -> str:
    """A per-workspace secret key, created on first use, so sessions survive restarts."""
    path = home / "secret_key"
    if not path.exists():
        atomic_write_bytes(path, secrets.token_hex(32).encode(), mode=0o600)
    return path.read_text().strip()


def _register_errors(app: Flask) -> None:
    def render(status: int, message: str) -> Any:
        if is_api_request():
            return json_error(status, message)
        return render_template("error.html", status=status, message=message), status

    @app.errorhandler(ServiceError)
    def _service_error(exc: ServiceError) -> Any:
        field = getattr(exc, "field", None)  # a launch's wrong field, which the forms mark
        if field and is_api_request():
            return jsonify(error=str(exc), status=exc.status, field=field, reason=exc.reason), exc.status
        return render(exc.status, str(exc))

    @app.errorhandler(CSRFError)
    def _csrf_error(exc: CSRFError) -> Any:
        return render(400, f"CSRF check failed: {exc.description}; reload the page and try again")

    @app.errorhandler(HTTPException)
    def _http_error(exc: HTTPException) -> Any:
        response = make_response(render(exc.code or 500, exc.description or exc.name))
        for name, value in exc.get_headers():  # e.g. Retry-After of a 429
            if name.lower() != "content-type":
                response.headers[name] = value
        return response
