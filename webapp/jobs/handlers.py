"""Which service runs each job kind. Add a kind here and it can be enqueued and run."""

from __future__ import annotations

from dataset.services.jobs import Handler
from dataset.services.synthetic_import import import_synthetic_video

HANDLERS: dict[str, Handler] = {
    "import_synthetic": import_synthetic_video,
}
