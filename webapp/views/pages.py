"""Pages: login, dashboard, frames, jobs, and user administration."""

from __future__ import annotations

from urllib.parse import urlsplit

from flask import Blueprint, flash, g, redirect, render_template, request, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user, login_user, logout_user
from sqlalchemy import select

from annotation.vlm import QUESTION_LABELS
from dataset.ingest.sources import VIDEO_EXTENSIONS
from dataset.models import IllusionType, Role, SourceKind, User, Video
from dataset.services import users as user_service
from dataset.services.annotate import DELETE_REASONS
from dataset.services.errors import ServiceError
from dataset.services.frames import FUNNEL_STAGES, funnel_counts
from dataset.services.review import REJECT_REASONS
from webapp.app import runtime
from webapp.auth import SessionUser, public, requires
from webapp.forms import CreateUserForm, LoginForm

pages = Blueprint("pages", __name__)


@pages.get("/healthz")
@public
def healthz() -> ResponseReturnValue:
    g.db.execute(select(1))
    return {"status": "ok"}


@pages.route("/login", methods=["GET", "POST"])
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
    return url_for("pages.dashboard")


@pages.post("/logout")
@requires(Role.annotator)
def logout() -> ResponseReturnValue:
    logout_user()
    flash("Logged out.", "info")
    return redirect(url_for("pages.login"))


@pages.get("/")
@requires(Role.annotator)
def dashboard() -> ResponseReturnValue:
    return render_template("dashboard.html", counts=funnel_counts(g.db), stages=FUNNEL_STAGES)


@pages.get("/frames")
@requires(Role.annotator)
def frames() -> ResponseReturnValue:
    return render_template("frames.html")


@pages.get("/jobs")
@requires(Role.annotator)
def jobs() -> ResponseReturnValue:
    return render_template("jobs.html")


@pages.get("/annotate")
@pages.get("/annotate/<int:frame_id>")
@requires(Role.annotator)
def annotate(frame_id: int | None = None) -> ResponseReturnValue:
    """The click-annotation canvas; without a frame id it asks the queue for the next frame."""
    return render_template("annotate.html", frame_id=frame_id, illusion_types=list(IllusionType),
                           delete_reasons=DELETE_REASONS, lease_s=runtime().settings.annotation_lease_s)


@pages.get("/review")
@requires(Role.curator)
def review() -> ResponseReturnValue:
    """The curators' review grid (per video with ?video_id=N)."""
    video_id = request.args.get("video_id", type=int)
    video = g.db.get(Video, video_id) if video_id else None
    return render_template("review.html", video=video, reasons=REJECT_REASONS, questions=QUESTION_LABELS)


@pages.get("/ingest")
@requires(Role.curator)
def ingest() -> ResponseReturnValue:
    """Upload videos; each becomes an ingest job."""
    return render_template("ingest.html", sources=list(SourceKind), illusion_types=list(IllusionType),
                           max_upload_mb=runtime().settings.max_upload_mb,
                           extensions=sorted(VIDEO_EXTENSIONS))


@pages.get("/admin/users")
@requires(Role.admin)
def users() -> ResponseReturnValue:
    return _users_page(CreateUserForm())


@pages.post("/admin/users")
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
    return redirect(url_for("pages.users"))


def _users_page(form: CreateUserForm) -> str:
    rows = g.db.scalars(select(User).order_by(User.name)).all()
    return render_template("users.html", users=rows, form=form, me=current_user)
