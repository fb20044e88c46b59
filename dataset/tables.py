"""The database schema: SQLAlchemy 2 typed ORM models.

Every table is created by an Alembic migration (``dataset/migrations``); a test checks that the
migrations and these models agree. Enums are stored as strings with CHECK constraints so that
SQLite and PostgreSQL behave the same.
"""

from __future__ import annotations

import enum
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import JSON, Enum, ForeignKey, Index, MetaData, String, Text, UniqueConstraint
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

from dataset.states import (
    FrameState,
    IllusionType,
    JobState,
    ProposalFate,
    RegionKind,
    ReviewDecision,
    Role,
    RunState,
    SampleState,
    SourceKind,
)

NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


def utcnow() -> datetime:
    return datetime.now(UTC).replace(tzinfo=None)


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING)
    type_annotation_map = {dict[str, Any]: JSON, list[Any]: JSON}


def _enum(cls: type[enum.Enum]) -> Enum:
    return Enum(
        cls,
        native_enum=False,
        create_constraint=True,
        length=32,
        name=cls.__name__.lower(),
        values_callable=lambda members: [m.value for m in members],
        validate_strings=True,
    )


class User(Base):
    __tablename__ = "users"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    password_hash: Mapped[str] = mapped_column(String(256))
    role: Mapped[Role] = mapped_column(_enum(Role))
    active: Mapped[bool] = mapped_column(default=True)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)

    tokens: Mapped[list[ApiToken]] = relationship(back_populates="user", cascade="all, delete-orphan")


class ApiToken(Base):
    """A script's bearer token ``ist_<id>_<secret>``; only its secret's SHA-256 is stored (of the
    whole token for the old ``ist_<secret>`` form)."""

    __tablename__ = "api_tokens"

    id: Mapped[int] = mapped_column(primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), index=True)
    token_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    label: Mapped[str] = mapped_column(String(128), default="")
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    last_used_at: Mapped[datetime | None]

    user: Mapped[User] = relationship(back_populates="tokens")


class UserSession(Base):
    """A signed-in browser: its id rides in the cookie, and deleting the row ends the session."""

    __tablename__ = "user_sessions"

    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), index=True)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    last_seen_at: Mapped[datetime] = mapped_column(default=utcnow)


class Video(Base):
    __tablename__ = "videos"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(256))
    source_kind: Mapped[SourceKind] = mapped_column(_enum(SourceKind))
    illusion_types: Mapped[list[Any]] = mapped_column(default=list)
    content_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    original_path: Mapped[str] = mapped_column(Text, default="")
    fps: Mapped[float | None]
    width: Mapped[int | None]
    height: Mapped[int | None]
    meta: Mapped[dict[str, Any]] = mapped_column(default=dict)
    created_by_id: Mapped[int | None] = mapped_column(ForeignKey("users.id", ondelete="SET NULL"))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    scene_group: Mapped[int | None] = mapped_column(
        doc="Id of the first video of its scene group (copies of one scene split together); None: its own.")

    frames: Mapped[list[Frame]] = relationship(back_populates="video", order_by="Frame.index", passive_deletes=True)


class Frame(Base):
    __tablename__ = "frames"
    __table_args__ = (
        UniqueConstraint("video_id", "index", name="uq_frames_video_index"),
        # One index per grid filter, each ending in the grids' order, so a page is a range scan.
        Index("ix_frames_state_video_index", "state", "video_id", "index"),
        Index("ix_frames_state_keep_video_index", "state", "prefilter_keep", "video_id", "index"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    video_id: Mapped[int] = mapped_column(ForeignKey("videos.id", ondelete="CASCADE"))
    index: Mapped[int] = mapped_column(doc="Frame number in the decoded video.")
    time_s: Mapped[float] = mapped_column(doc="Seconds from the start of the video.")
    width: Mapped[int]
    height: Mapped[int]
    content_sha256: Mapped[str] = mapped_column(String(64), index=True)
    media_key: Mapped[str] = mapped_column(String(128), doc="Left image in the media store.")
    state: Mapped[FrameState] = mapped_column(_enum(FrameState), default=FrameState.ingested)
    revision: Mapped[int] = mapped_column(default=1, doc="Bumped on every change; stale writes get 409.")
    assets: Mapped[dict[str, Any]] = mapped_column(
        default=dict, doc="Media keys of side data: thumbnail, and ground truth imported with the frame."
    )
    prefilter_job_id: Mapped[int | None] = mapped_column(
        ForeignKey("jobs.id", ondelete="SET NULL"), doc="The prefilter job that has claimed this frame.")
    # The newest prefilter verdict, kept by a database trigger on prefilter_results (migration 0002), so
    # the review grid filters and pages by it without grouping every verdict.
    prefilter_result_id: Mapped[int | None] = mapped_column(doc="Id of the newest prefilter result.")
    prefilter_keep: Mapped[bool | None] = mapped_column(doc="Its keep verdict (null: undecided or none yet).")
    updated_at: Mapped[datetime] = mapped_column(default=utcnow, onupdate=utcnow)

    video: Mapped[Video] = relationship(back_populates="frames")


class FrameCount(Base):
    """How many frames each (video, state, verdict) holds; kept by triggers on ``frames`` (migration
    0002) in the writing transaction, so totals and the funnel never count the frames table."""

    __tablename__ = "frame_counts"

    video_id: Mapped[int] = mapped_column(primary_key=True, autoincrement=False)
    state: Mapped[FrameState] = mapped_column(_enum(FrameState), primary_key=True)
    keep: Mapped[int] = mapped_column(primary_key=True, autoincrement=False, doc="prefilter_keep: 1, 0, or -1 for null.")
    n: Mapped[int]


class PrefilterResult(Base):
    __tablename__ = "prefilter_results"

    id: Mapped[int] = mapped_column(primary_key=True)
    frame_id: Mapped[int] = mapped_column(ForeignKey("frames.id", ondelete="CASCADE"), index=True)
    backend: Mapped[str] = mapped_column(String(64))
    model_id: Mapped[str] = mapped_column(String(256))
    prompt_version: Mapped[str] = mapped_column(String(32))
    raw_answer: Mapped[str] = mapped_column(Text, default="")
    answers: Mapped[list[Any]] = mapped_column(default=list, doc="12 entries: true, false or null (unknown).")
    parsed: Mapped[bool] = mapped_column(default=False)
    keep: Mapped[bool | None]
    reason: Mapped[str] = mapped_column(Text, default="", doc="Why keep is what it is, naming the questions.")
    metrics: Mapped[dict[str, Any]] = mapped_column(default=dict, doc="Measured figures, name → number.")
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class Review(Base):
    __tablename__ = "reviews"

    id: Mapped[int] = mapped_column(primary_key=True)
    frame_id: Mapped[int] = mapped_column(ForeignKey("frames.id", ondelete="CASCADE"), index=True)
    user_id: Mapped[int | None] = mapped_column(ForeignKey("users.id", ondelete="SET NULL"))
    decision: Mapped[ReviewDecision] = mapped_column(_enum(ReviewDecision))
    reason: Mapped[str] = mapped_column(String(256), default="")
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class Annotation(Base):
    __tablename__ = "annotations"
    __table_args__ = (Index("ix_annotations_user_updated", "user_id", "updated_at"),
                      Index("ix_annotations_lease_user_id", "lease_user_id"))

    id: Mapped[int] = mapped_column(primary_key=True)
    frame_id: Mapped[int] = mapped_column(ForeignKey("frames.id", ondelete="CASCADE"), unique=True)
    user_id: Mapped[int | None] = mapped_column(ForeignKey("users.id", ondelete="SET NULL"))
    version: Mapped[int] = mapped_column(default=0)
    illusion_type: Mapped[IllusionType | None] = mapped_column(_enum(IllusionType))
    submitted: Mapped[bool] = mapped_column(default=False)
    lease_user_id: Mapped[int | None] = mapped_column(ForeignKey("users.id", ondelete="SET NULL"))
    lease_expires_at: Mapped[datetime | None]
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow, onupdate=utcnow)

    regions: Mapped[list[Region]] = relationship(
        back_populates="annotation", cascade="all, delete-orphan", order_by="(Region.pair, Region.kind)"
    )


class Region(Base):
    """One mask of an illusion/support pair; ``mask_rle`` is COCO RLE (pycocotools)."""

    __tablename__ = "regions"
    __table_args__ = (UniqueConstraint("annotation_id", "pair", "kind", name="uq_regions_pair_kind"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    annotation_id: Mapped[int] = mapped_column(ForeignKey("annotations.id", ondelete="CASCADE"))
    pair: Mapped[int]
    kind: Mapped[RegionKind] = mapped_column(_enum(RegionKind))
    mask_rle: Mapped[dict[str, Any]] = mapped_column(default=dict)
    clicks: Mapped[list[Any]] = mapped_column(default=list)
    illusion_type: Mapped[IllusionType | None] = mapped_column(
        _enum(IllusionType), doc="The pair's illusion type (a frame can hold a picture and a mirror); None: the annotation's.")

    annotation: Mapped[Annotation] = relationship(back_populates="regions")


class Sample(Base):
    """A generated stereo training sample and everything needed to judge and reproduce it."""

    __tablename__ = "samples"
    __table_args__ = (UniqueConstraint("frame_id", "annotation_version", name="uq_samples_frame_version"),
                      Index("ix_samples_state_id", "state", "id"), Index("ix_samples_flagged_id", "flagged", "id"))

    id: Mapped[int] = mapped_column(primary_key=True)
    frame_id: Mapped[int] = mapped_column(ForeignKey("frames.id", ondelete="CASCADE"), index=True)
    annotation_version: Mapped[int | None]
    state: Mapped[SampleState] = mapped_column(_enum(SampleState), default=SampleState.generated)
    flagged: Mapped[bool] = mapped_column(default=False)
    files: Mapped[dict[str, Any]] = mapped_column(default=dict, doc="Output name → media key.")
    params: Mapped[dict[str, Any]] = mapped_column(default=dict)
    provenance: Mapped[dict[str, Any]] = mapped_column(default=dict)
    qa: Mapped[dict[str, Any]] = mapped_column(default=dict)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class SampleCount(Base):
    """How many samples each (state, flagged) holds; kept by triggers on ``samples`` (migration 0002)."""

    __tablename__ = "sample_counts"

    state: Mapped[SampleState] = mapped_column(_enum(SampleState), primary_key=True)
    flagged: Mapped[bool] = mapped_column(primary_key=True)
    n: Mapped[int]


class Job(Base):
    """A long-running step; the worker mirrors its state, progress and log here."""

    __tablename__ = "jobs"
    __table_args__ = (Index("ix_jobs_state_id", "state", "id"), Index("ix_jobs_created_by_id", "created_by_id", "id"))

    id: Mapped[int] = mapped_column(primary_key=True)
    kind: Mapped[str] = mapped_column(String(64), index=True)
    state: Mapped[JobState] = mapped_column(_enum(JobState), default=JobState.queued)
    progress: Mapped[float] = mapped_column(default=0.0, doc="0..1")
    params: Mapped[dict[str, Any]] = mapped_column(default=dict)
    result: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    error: Mapped[str | None] = mapped_column(Text)
    log: Mapped[str] = mapped_column(Text, default="")
    attempts: Mapped[int] = mapped_column(default=0)
    ran_s: Mapped[float] = mapped_column(default=0.0, server_default="0",
                                         doc="Seconds its attempts before the current one ran (a retry adds the last).")
    worker: Mapped[str | None] = mapped_column(String(128), doc="host:pid of the worker running it.")
    created_by_id: Mapped[int | None] = mapped_column(ForeignKey("users.id", ondelete="SET NULL"))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    started_at: Mapped[datetime | None]
    finished_at: Mapped[datetime | None]
    heartbeat_at: Mapped[datetime | None]

    created_by: Mapped[User | None] = relationship()
    # The run a train job trains (its row points here): what the job's answer says of a cancelled run.
    training_run: Mapped[TrainingRun | None] = relationship(viewonly=True, uselist=False)


class TrainingRun(Base):
    """One training of the fusion model: what it trains on (a pinned dataset version), how, and how far it got.

    The run directory ``<home>/runs/<id>/`` holds ``run.json`` (the engine's input) and what the
    engine writes; the row mirrors the engine's ``progress.jsonl`` for the pages.
    """

    __tablename__ = "training_runs"

    id: Mapped[int] = mapped_column(primary_key=True)
    state: Mapped[RunState] = mapped_column(_enum(RunState), default=RunState.queued, index=True)
    preset: Mapped[str] = mapped_column(String(32))
    config: Mapped[dict[str, Any]] = mapped_column(default=dict, doc="The engine's Config.to_dict().")
    launch: Mapped[dict[str, Any]] = mapped_column(
        default=dict, doc="How it was asked for: data selection, split fractions, seed, processes, devices, init.")
    dataset_id: Mapped[str] = mapped_column(String(64), default="", doc="SHA-256 of the pinned version's items.")
    dataset: Mapped[dict[str, Any]] = mapped_column(default=dict, doc="The pinned dataset version.")
    splits: Mapped[dict[str, Any]] = mapped_column(default=dict, doc="split name → sample ids (or names).")
    job_id: Mapped[int | None] = mapped_column(ForeignKey("jobs.id", ondelete="SET NULL"))
    created_by_id: Mapped[int | None] = mapped_column(ForeignKey("users.id", ondelete="SET NULL"))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    started_at: Mapped[datetime | None]
    finished_at: Mapped[datetime | None]
    cancel_requested: Mapped[bool] = mapped_column(default=False, doc="Set by cancel; the job stops the trainers.")
    step: Mapped[int] = mapped_column(default=0)
    steps: Mapped[int] = mapped_column(default=0)
    world_size: Mapped[int | None]
    resumed_from_step: Mapped[int | None]
    loss: Mapped[float | None]
    lr: Mapped[float | None]
    samples_per_s: Mapped[float | None]
    eta_s: Mapped[float | None]
    best_val_epe: Mapped[float | None]
    best_step: Mapped[int | None]
    last_val: Mapped[dict[str, Any]] = mapped_column(default=dict, doc="The newest validation event.")
    last_checkpoint: Mapped[str | None] = mapped_column(Text, doc="Relative to the run directory.")
    progress_offset: Mapped[int] = mapped_column(default=0, doc="Bytes of progress.jsonl already mirrored.")
    reason: Mapped[str | None] = mapped_column(Text, doc="Why it failed, diverged or was cancelled.")

    job: Mapped[Job | None] = relationship()
    created_by: Mapped[User | None] = relationship()


class TrainingMetric(Base):
    """One point of a run's curves: a training step (loss, lr, …) or a validation (metrics per region)."""

    __tablename__ = "training_metrics"
    __table_args__ = (UniqueConstraint("run_id", "kind", "step", name="uq_training_metrics_point"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("training_runs.id", ondelete="CASCADE"))
    kind: Mapped[str] = mapped_column(String(16), doc="step or val")
    step: Mapped[int]
    values: Mapped[dict[str, Any]] = mapped_column(default=dict)


class Evaluation(Base):
    """One evaluation job: methods on a dataset folder or a run's test split; the report lives in ``report_dir``."""

    __tablename__ = "evaluations"

    id: Mapped[int] = mapped_column(primary_key=True)
    job_id: Mapped[int | None] = mapped_column(ForeignKey("jobs.id", ondelete="SET NULL"), index=True)
    created_by_id: Mapped[int | None] = mapped_column(ForeignKey("users.id", ondelete="SET NULL"))
    created_at: Mapped[datetime] = mapped_column(default=utcnow, index=True)
    dataset: Mapped[str] = mapped_column(Text, doc="The folder, or 'test split of <run dir>'.")
    params: Mapped[dict[str, Any]] = mapped_column(default=dict, doc="The job's evaluation_params.")
    summary: Mapped[dict[str, Any]] = mapped_column(default=dict, doc="method → region → {epe, bad2}; samples, failed.")
    report_dir: Mapped[str | None] = mapped_column(Text)

    job: Mapped[Job | None] = relationship()
    created_by: Mapped[User | None] = relationship()


class EvaluationResult(Base):
    """One method's figures on one database sample: every region's metrics, and EPE / bad-2 on ``all``
    and ``illusion`` as columns, indexed for sorting the Samples pages by error."""

    __tablename__ = "evaluation_results"
    __table_args__ = (UniqueConstraint("evaluation_id", "method", "sample_id", name="uq_evaluation_results_row"),
                      Index("ix_evaluation_results_epe_all", "evaluation_id", "method", "epe_all", "sample_id"),
                      Index("ix_evaluation_results_epe_illusion", "evaluation_id", "method", "epe_illusion",
                            "sample_id"))

    id: Mapped[int] = mapped_column(primary_key=True)
    evaluation_id: Mapped[int] = mapped_column(ForeignKey("evaluations.id", ondelete="CASCADE"))
    sample_id: Mapped[int] = mapped_column(ForeignKey("samples.id", ondelete="CASCADE"), index=True)
    method: Mapped[str] = mapped_column(String(32))
    regions: Mapped[dict[str, Any]] = mapped_column(default=dict, doc="region → metrics (EPE px, bad-x %).")
    prediction: Mapped[str | None] = mapped_column(Text, doc="The PFM's path under the report's predictions/<method>/.")
    epe_all: Mapped[float | None]
    bad2_all: Mapped[float | None]
    epe_illusion: Mapped[float | None]
    bad2_illusion: Mapped[float | None]


class AuditEntry(Base):
    """Every human decision: who, what, on which object, when."""

    __tablename__ = "audit_log"
    # What was decided about one object (why a sample was rejected, for its annotator), without a scan.
    __table_args__ = (Index("ix_audit_log_target", "target_kind", "target_id"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    user_id: Mapped[int | None] = mapped_column(ForeignKey("users.id", ondelete="SET NULL"), index=True)
    action: Mapped[str] = mapped_column(String(64))
    target_kind: Mapped[str] = mapped_column(String(32))
    target_id: Mapped[int | None]
    detail: Mapped[dict[str, Any]] = mapped_column(default=dict)
    created_at: Mapped[datetime] = mapped_column(default=utcnow, index=True)


class ProposalScan(Base):
    """One proposer having looked at one frame: its ``note`` says why it found nothing when it could
    not look; ``misses`` (set on submit) counts the submitted illusions none of its proposals matched."""

    __tablename__ = "proposal_scans"
    __table_args__ = (UniqueConstraint("frame_id", "source", name="uq_proposal_scans_frame_source"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    frame_id: Mapped[int] = mapped_column(ForeignKey("frames.id", ondelete="CASCADE"))
    source: Mapped[str] = mapped_column(String(32), index=True, doc="The proposer's name.")
    content_sha256: Mapped[str] = mapped_column(String(64), doc="The frame content it looked at.")
    note: Mapped[str] = mapped_column(Text, default="")
    seconds: Mapped[float] = mapped_column(default=0.0, doc="Wall time the proposer took on the frame.")
    misses: Mapped[int | None] = mapped_column(doc="Submitted illusions it did not find (IoU < 0.5); null until submit.")
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    threshold: Mapped[float] = mapped_column(default=0.0, server_default="0",
                                             doc="Score under which its proposals were hidden (setting proposal_threshold).")

    proposals: Mapped[list[Proposal]] = relationship(back_populates="scan", cascade="all, delete-orphan",
                                                     order_by="Proposal.rank")


class Proposal(Base):
    """A machine-proposed illusion/support pair (COCO RLE masks) and its fate."""

    __tablename__ = "proposals"
    __table_args__ = (Index("ix_proposals_frame_id", "frame_id"), Index("ix_proposals_source_fate", "source", "fate"))

    id: Mapped[int] = mapped_column(primary_key=True)
    scan_id: Mapped[int] = mapped_column(ForeignKey("proposal_scans.id", ondelete="CASCADE"), index=True)
    frame_id: Mapped[int] = mapped_column(ForeignKey("frames.id", ondelete="CASCADE"))
    source: Mapped[str] = mapped_column(String(32))
    rank: Mapped[int] = mapped_column(doc="0 = the proposer's best.")
    type_guess: Mapped[str | None] = mapped_column(String(32), doc="picture | mirror | transparent, or none.")
    score: Mapped[float]
    illusion_rle: Mapped[dict[str, Any]] = mapped_column(default=dict)
    support_rle: Mapped[dict[str, Any]] = mapped_column(default=dict)
    fate: Mapped[ProposalFate] = mapped_column(_enum(ProposalFate), default=ProposalFate.pending)
    iou: Mapped[float | None] = mapped_column(doc="IoU of the proposed and the submitted illusion (accepted/edited).")
    decided_by: Mapped[int | None] = mapped_column(ForeignKey("users.id", ondelete="SET NULL"))
    decided_at: Mapped[datetime | None]

    scan: Mapped[ProposalScan] = relationship(back_populates="proposals")


class Export(Base):
    """A dataset export made from the web: its job writes ``<home>/exports/<id>``, and the page offers
    that folder as one zip until a curator deletes it or it outlives ``export_retention_days``."""

    __tablename__ = "exports"

    id: Mapped[int] = mapped_column(primary_key=True)
    job_id: Mapped[int | None] = mapped_column(ForeignKey("jobs.id", ondelete="SET NULL"))
    options: Mapped[dict[str, Any]] = mapped_column(
        default=dict, doc="What was asked: format, split, seed, states, video_ids, mask_format.")
    created_by_id: Mapped[int | None] = mapped_column(ForeignKey("users.id", ondelete="SET NULL"))
    created_at: Mapped[datetime] = mapped_column(default=utcnow, index=True)

    job: Mapped[Job | None] = relationship()
    created_by: Mapped[User | None] = relationship()
