"""Rendered synthetic videos imported as ground-truth captures."""

from __future__ import annotations

import numpy as np
from sqlalchemy import func, select

from dataset.capture.synthetic import import_rendered_video
from dataset.db import transaction
from dataset.readers.version import VersionReader, pin_dataset_version
from dataset.services import users as user_service
from dataset.services.sample_review import review_sample
from dataset.synthetic import render_video
from dataset.tables import Sample, SourceKind, Video
from webapp.runtime import Runtime


def test_rendered_pairs_become_accepted_captures_with_exact_truth(runtime: Runtime) -> None:
    video = render_video(5, n_frames=2, width=64, height=40)
    with transaction(runtime.sessions) as s:
        curator = user_service.create_user(s, "cur", "curator", "password-123")
        ids = import_rendered_video(s, runtime.media, video)
        for sample_id in ids:
            review_sample(s, sample_id, curator, "accept")
        assert import_rendered_video(s, runtime.media, video) == ids  # idempotent
        assert s.scalar(select(func.count()).select_from(Video)) == 1
        assert s.scalar(select(Video.source_kind)) == SourceKind.real_capture
    with runtime.sessions() as s:
        version = pin_dataset_version(s, runtime.media)
        assert s.scalar(select(func.count()).select_from(Sample)) == 2
    assert [item["kind"] for item in version["items"]] == ["capture", "capture"]
    sample = VersionReader(version, runtime.settings.media_root)[0]
    frame = video.frames[0]
    np.testing.assert_array_equal(sample.left, frame.left)
    np.testing.assert_array_equal(sample.right, frame.right)  # the raytraced right view, mirror reflections and all
    np.testing.assert_allclose(sample.disparity, frame.disparity)
    np.testing.assert_allclose(sample.mono, frame.mono_disparity)
    np.testing.assert_array_equal(sample.regions["illusion"], frame.regions[0].illusion | frame.regions[1].illusion)
