"""Which service runs each job kind. Add a kind here and it can be enqueued and run."""

from __future__ import annotations

from dataset.services.jobs import Handler
from dataset.services.ingest import ingest_video

HANDLERS: dict[str, Handler] = {
    "ingest": ingest_video,
}
