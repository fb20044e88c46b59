"""One 1080p sample end to end through the real generation job, timed in CPU seconds.

Budget (DESIGN.md): ≤ 1 s of CPU per 1080p frame, model inference aside — the synthetic scene's
recorded mono disparity stands in for the model. The reference is the same frame through the
straightforward implementations of the authors' steps (batched RANSAC on all points, iterated
scale search, ``np.maximum.at`` splat), measured in the same run.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import select

from benchmarks.workspace import approved_frame_workspace
from core.geometry.benchmark import reference_plane_fit, reference_right_view
from dataset.db import transaction
from dataset.services import jobs as job_service
from dataset.services import pipeline
from dataset.services.annotate import save_annotation
from dataset.services.demo import true_regions
from dataset.synthetic import read_video, write_synthetic_dataset
from dataset.tables import Frame, Job, Sample, User
from webapp.jobs.handlers import HANDLERS


def run_generate_bench(size: tuple[int, int] = (1920, 1080), repeats: int = 3) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        [scene] = write_synthetic_dataset(root / "scene", videos=1, seed=0, n_frames=1, width=size[0], height=size[1])
        rt, frame_id, user_id = approved_frame_workspace(root / "ws", scene)
        with transaction(rt.sessions) as s:
            frame = s.get(Frame, frame_id)
            save_annotation(s, frame_id, s.get(User, user_id), version=0, regions=true_regions(rt.media, frame, frame.video),
                            illusion_type=None, submit=True)
        cpu, wall = [], []
        for _ in range(repeats):
            with transaction(rt.sessions) as s:
                job_id = pipeline.submitted(s, rt.submit, pipeline.GenerateParams(frame_id), None).id
            started = time.perf_counter()
            job_service.run_queued_jobs(HANDLERS, rt)
            wall.append(time.perf_counter() - started)
            with rt.sessions() as s:
                job = s.get(Job, job_id)
                if job.state.value != "succeeded":
                    raise RuntimeError(f"generation failed: {job.error}")
                cpu.append(job.result["cpu_s"])
                qa = s.scalar(select(Sample)).qa
        reference_ms = _reference_ms(scene)
        rt.close()
    return {"size": f"{size[0]}x{size[1]}", "generate_cpu_s": round(float(np.median(cpu)), 3),
            "generate_wall_s": round(float(np.median(wall)), 3), "budget_cpu_s": 1.0,
            "reference_steps_ms": reference_ms, "hole_fraction": round(qa["hole_fraction"], 4),
            "stereo_epe": round(qa["stereo_epe"], 3), "repeats": repeats}


def _reference_ms(scene: Path) -> dict[str, float]:
    """The authors' straightforward steps on the same frame: plane fits on the support regions
    and the right view (iterated scale search + ``np.maximum.at`` splat)."""
    frame = read_video(scene).frames[0]
    started = time.perf_counter()
    for region in frame.regions:
        v, u = np.nonzero(region.support)
        d = frame.mono_disparity[v, u]
        points = np.stack([u, v, (d - d.min()) / max(float(np.ptp(d)), 1e-6)], axis=1).astype(np.float32)
        reference_plane_fit(points, threshold=0.01, hypotheses=1000, batch=10, seed=0)
    plane_ms = (time.perf_counter() - started) * 1000
    started = time.perf_counter()
    reference_right_view(frame.left, frame.mono_disparity, tau=0.9)
    return {"plane_fits_ms": round(plane_ms, 1), "right_view_ms": round((time.perf_counter() - started) * 1000, 1)}
