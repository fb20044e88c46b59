"""Scratch workspaces for benchmarks: ingested synthetic scenes, with their frames approved or their samples accepted."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sqlalchemy import select, update

from dataset.db import migrate, transaction
from dataset.readers.version import pin_dataset_version
from dataset.services import jobs as job_service
from dataset.services import pipeline
from dataset.services import users as user_service
from dataset.services.demo import seed_reviews_and_annotations
from dataset.services.ingest import ingest_params
from dataset.services.sample_review import review_sample
from dataset.settings import load_settings, write_settings_file
from dataset.synthetic import write_synthetic_dataset
from dataset.tables import Frame, FrameState, Sample, User
from model.presets import Config
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime


def ingested_workspace(home: Path, scenes: Sequence[Path], **settings: Any) -> Runtime:
    """A workspace in ``home`` with ``scenes`` ingested (as the real job does); ``settings`` go into its
    settings file, so the servers and workers started on it use them too."""
    home.mkdir(parents=True)
    write_settings_file(home, **settings)
    rt = Runtime(load_settings(home))
    migrate(rt.settings.database_url)
    with transaction(rt.sessions) as s:
        for scene in scenes:
            rt.submit(s, "ingest", ingest_params(str(scene), fps=None, dedup_hamming=None), None)
    job_service.run_queued_jobs(HANDLERS, rt)
    return rt


def approved_frame_workspace(home: Path, scene: Path, **settings: Any) -> tuple[Runtime, int, int]:
    """An :func:`ingested_workspace` of ``scene`` with every frame approved, plus an annotator named
    ``bench``; returns (runtime, first frame's id, user id)."""
    rt = ingested_workspace(home, [scene], **settings)
    with transaction(rt.sessions) as s:
        s.execute(update(Frame).values(state=FrameState.approved))
        frame_id = s.scalar(select(Frame.id).order_by(Frame.index))
        user_id = user_service.create_user(s, "bench", "annotator", "bench-password").id
    return rt, frame_id, user_id


def accepted_samples_workspace(home: Path, scenes: list[Path]) -> Runtime:
    """An :func:`ingested_workspace` of ``scenes`` with the demo's head start of reviews and
    annotations, their samples generated and accepted by a curator (as the real jobs do)."""
    rt = ingested_workspace(home, scenes)
    with transaction(rt.sessions) as s:
        s.execute(update(Frame).values(state=FrameState.prefiltered))
        curator = user_service.create_user(s, "bench-curator", "curator", "bench-password")
        annotator = user_service.create_user(s, "bench-annotator", "annotator", "bench-password")
        for frame_id in seed_reviews_and_annotations(s, rt.media, curator, annotator):
            pipeline.submitted(s, rt.submit, pipeline.GenerateParams(frame_id), None)
    job_service.run_queued_jobs(HANDLERS, rt)
    with transaction(rt.sessions) as s:
        curator = s.scalar(select(User).where(User.name == "bench-curator"))
        for sample_id in s.scalars(select(Sample.id).order_by(Sample.id)).all():
            review_sample(s, sample_id, curator, "accept")
    return rt


def synthetic_version(root: Path, *, width: int, height: int, n_frames: int) -> tuple[dict[str, Any], Path]:
    """One synthetic video of ``n_frames`` at ``width``×``height`` px made into accepted samples the
    product's way, in a scratch workspace under ``root``: (its pinned dataset version, media root)."""
    scenes = write_synthetic_dataset(root / "scenes", videos=1, seed=0, n_frames=n_frames, width=width, height=height)
    rt = accepted_samples_workspace(root / "ws", scenes)
    try:
        with rt.sessions() as s:
            return pin_dataset_version(s, rt.media), rt.media.root
    finally:
        rt.close()


def write_train_run(run_dir: Path, config: Config, version: dict[str, Any], media_root: Path) -> None:
    """``run_dir/run.json`` for ``python -m model.train``: every sample of ``version`` in training, on CPU."""
    run_dir.mkdir(parents=True)
    ids = [item["sample_id"] for item in version["items"]]
    (run_dir / "run.json").write_text(json.dumps({
        "config": config.to_dict(), "dataset": version, "media_root": str(media_root), "init_checkpoint": None,
        "device": "cpu", "splits": {"train": ids, "val": [], "test": []},
        "data": {"format": "database", "root": None}}))
