"""Shared fixtures: workspaces on SQLite (always) and PostgreSQL (when TEST_DATABASE_URL is set),
an app with one user per role, and their API tokens."""

from __future__ import annotations

import functools
import os
import re
import sqlite3
import uuid
from collections.abc import Iterator
from contextlib import closing
from pathlib import Path

import pytest
from werkzeug import security

from dataset.db import make_engine, make_session_factory, migrate, scratch_database, transaction
from dataset.services import users as user_service
from dataset.settings import Settings, load_settings
from dataset.tables import Role
from webapp.runtime import Runtime

# Fixtures shared between test modules live in plugin modules, never imported by the tests:
# - tests.browser: one browser per test session, for every browser test module (a fixture defined in
#   two modules would start two Playwright loops, and the second refuses to run);
# - tests.workers: real worker processes over a real queue (``queue_settings``, ``rt``, ``start_worker``);
# - tests.fixtures.*: workspaces and data shared by several modules.
pytest_plugins = [
    "tests.file_durations",  # before crash_safe_scheduling, which imports it
    "tests.crash_safe_scheduling",
    "tests.browser",
    "tests.workers",
    "tests.fixtures.workspaces",
    "tests.fixtures.annotate",
    "tests.fixtures.login_flood",
    "tests.fixtures.runs",
]

TEST_DATABASE_URL = os.environ.get("TEST_DATABASE_URL", "")
TEST_REDIS_URL = os.environ.get("TEST_REDIS_URL", "")
PASSWORD = "correct-horse-battery"


def pytest_configure(config: pytest.Config) -> None:
    """One thread per test process, set before any test module imports torch: on 2 cores torch's own
    default oversubscribes them (with two xdist workers, each spinning a thread per core), and the
    model tests run ~10x slower."""
    for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ.setdefault(name, "1")


# The real hash (scrypt) costs 0.09 s of CPU a password; hundreds of tests create users. Tests of the
# hashing itself are marked `password_hashing` and get the real one.
FAST_PASSWORD_HASH = functools.partial(security.generate_password_hash, method="pbkdf2:sha256:1")
user_service.generate_password_hash = FAST_PASSWORD_HASH  # type: ignore[assignment]


@pytest.fixture(autouse=True)
def _password_hash(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    if request.node.get_closest_marker("password_hashing"):
        monkeypatch.setattr(user_service, "generate_password_hash", security.generate_password_hash)


@pytest.fixture(autouse=True)
def _clean_env(monkeypatch: pytest.MonkeyPatch) -> None:
    """Tests build their settings explicitly; a developer's own ILLUSION_STUDIO_* must not leak in."""
    for key in list(os.environ):
        if key.startswith("ILLUSION_STUDIO_"):
            monkeypatch.delenv(key)


@pytest.fixture
def postgres_url() -> Iterator[str]:
    """A fresh, empty PostgreSQL database for one test, dropped afterwards."""
    if not TEST_DATABASE_URL:
        pytest.skip("PostgreSQL tests need TEST_DATABASE_URL (e.g. postgresql://postgres@127.0.0.1:5432/test)")
    with scratch_database(TEST_DATABASE_URL, f"illusion_test_{uuid.uuid4().hex[:12]}") as url:
        yield url


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """The data layer runs on both backends."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'test.db'}"
    return request.getfixturevalue("postgres_url")


@pytest.fixture
def sessions(db_url: str):  # type: ignore[no-untyped-def]
    """A session factory on a migrated database of each backend."""
    migrate(db_url)
    engine = make_engine(db_url)
    yield make_session_factory(engine)
    engine.dispose()


def make_settings(home: Path, **overrides: object) -> Settings:
    home.mkdir(parents=True, exist_ok=True)
    return load_settings(home, **overrides)


@pytest.fixture(scope="session")
def migrated_sqlite(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An empty SQLite database migrated to the newest schema once per test process, for
    :func:`migrate_copying` to copy (a copy takes a millisecond, a migration most of a second)."""
    home = tmp_path_factory.mktemp("migrated")
    migrate(f"{SQLITE_PREFIX}{home / 'template.db'}")
    return home / "template.db"


SQLITE_PREFIX = "sqlite:///"


def migrate_copying(url: str, template: Path) -> None:
    """:func:`migrate` the database at ``url``: a SQLite file not there yet becomes a copy of ``template``,
    made by SQLite's backup API (consistent whatever the template's WAL still holds)."""
    if url.startswith(SQLITE_PREFIX) and not Path(url.removeprefix(SQLITE_PREFIX)).exists():
        with closing(sqlite3.connect(template)) as src, closing(sqlite3.connect(url.removeprefix(SQLITE_PREFIX))) as dst:
            src.backup(dst)
    else:
        migrate(url)


@pytest.fixture
def settings(tmp_path: Path, migrated_sqlite: Path) -> Settings:
    s = make_settings(tmp_path / "ws")
    migrate_copying(s.database_url, migrated_sqlite)
    return s


@pytest.fixture
def runtime(settings: Settings) -> Iterator[Runtime]:
    rt = Runtime(settings)
    yield rt
    rt.close()


@pytest.fixture
def tokens(runtime: Runtime) -> dict[str, str]:
    """One user per role (named after the role) and a bearer token for each."""
    out = {}
    with transaction(runtime.sessions) as s:
        for role in Role:
            user = user_service.create_user(s, role.value, role, PASSWORD)
            out[role.value] = user_service.issue_token(s, user)
    return out


@pytest.fixture
def app(settings: Settings, runtime: Runtime, tokens: dict[str, str]):  # type: ignore[no-untyped-def]
    from webapp.app import create_app

    application = create_app(settings, runtime)
    application.config["TESTING"] = True
    return application


@pytest.fixture
def client(app):  # type: ignore[no-untyped-def]
    return app.test_client()


def csrf_from(html: str) -> str:
    match = re.search(r'name="csrf_token"[^>]*value="([^"]+)"', html) or re.search(
        r'<meta name="csrf-token" content="([^"]+)"', html)
    assert match, "page carries no CSRF token"
    return match.group(1)


def login(client, name: str, password: str = PASSWORD):  # type: ignore[no-untyped-def]
    token = csrf_from(client.get("/login").get_data(as_text=True))
    return client.post("/login", data={"name": name, "password": password, "csrf_token": token})

