"""A database evaluation for tests: accepted samples, a run folder whose test split holds them all,
and a ``predictions`` folder whose error grows with the sample (0, 0.5, 1, … px), evaluated by the
real job in this process."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from core.atomic import atomic_write_bytes
from core.formats import write_pfm
from dataset.db import transaction
from dataset.readers.version import pin_dataset_version
from dataset.services import jobs as job_service
from dataset.services import training
from dataset.tables import Sample, TrainingRun
from model.runs.evaluation import EvalShellOptions, evaluation_params
from model.runs.schema import EvaluationLaunch, validate
from tests.runs_data import DISPARITY, H, W, add_accepted_samples
from webapp.jobs.handlers import HANDLERS
from webapp.runtime import Runtime

STEP_PX = 0.5


def evaluated_database(rt: Runtime, tmp: Path, videos: int = 3) -> tuple[int, list[int]]:
    """Runs an evaluate job (methods predictions and sgbm) on every accepted sample; returns the job id and
    the sample ids, best first (sample k is predicted ``k × STEP_PX`` px off)."""
    with transaction(rt.sessions) as s:
        ids = add_accepted_samples(s, rt.media, videos=videos)
        version = pin_dataset_version(s, rt.media)
        lefts = {sid: s.get(Sample, sid).files["left"] for sid in ids}
        for sid in ids:  # the sample page reads the generator's QA figures
            s.get(Sample, sid).qa = {"flags": [], "hole_fraction": 0.0}
        run = TrainingRun(preset="lite", config={}, dataset_id=version["id"], dataset=version,
                          splits={"train": [], "val": [], "test": ids}, launch={})
        s.add(run)
        s.flush()
        run_id = run.id
    run_dir = training.run_dir(rt.settings.runs_dir, run_id)
    atomic_write_bytes(run_dir / "run.json", json.dumps(
        {"config": {}, "dataset": version, "splits": {"train": [], "val": [], "test": ids},
         "media_root": str(rt.settings.media_root), "init_checkpoint": None, "data": {"format": "database"}}).encode())
    predictions = tmp / "predictions"
    for k, sid in enumerate(ids):
        path = predictions / Path(lefts[sid]).with_suffix(".pfm")
        path.parent.mkdir(parents=True, exist_ok=True)
        write_pfm(path, np.full((H, W), DISPARITY + k * STEP_PX, np.float32))
    request = validate(EvaluationLaunch, {"methods": ["predictions", "sgbm"], "run": run_id})
    with transaction(rt.sessions) as s:
        params = evaluation_params(request, rt.settings, s, EvalShellOptions(predictions=predictions))
        job_id = job_service.create_job(s, "evaluate", params, None).id
    assert job_service.execute_job(job_id, {"evaluate": HANDLERS["evaluate"]}, rt).value == "succeeded"
    return job_id, ids
