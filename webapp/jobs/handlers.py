"""Which service runs each job kind. Add a kind here and it can be enqueued and run."""

from __future__ import annotations

from dataset.capture import import_capture_job, import_reconstruction_job
from dataset.export.handlers import export_job, import_job
from dataset.services.generate import generate_job
from dataset.services.ingest import ingest_video
from dataset.services.jobs import Handler
from dataset.services.prefilter import prefilter_frames
from dataset.services.proposals import propose_job
from dataset.services.segmentation import encode_job, propagate_job
from model.runs.handlers import evaluate_job, train_job

HANDLERS: dict[str, Handler] = {
    "ingest": ingest_video,
    "prefilter": prefilter_frames,
    "encode": encode_job,
    "propose": propose_job,
    "propagate": propagate_job,
    "generate": generate_job,
    "import_capture": import_capture_job,
    "import_reconstruction": import_reconstruction_job,
    "export": export_job,
    "import": import_job,
    "train": train_job,
    "evaluate": evaluate_job,
}
