"""What a run tells the product: ``progress.jsonl`` (one JSON event a line, append-only) and
TensorBoard event files under ``RUN_DIR/tensorboard`` (rank 0 writes both)."""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any

from torch.utils.tensorboard import SummaryWriter

from dataset.run_layout import PROGRESS_FILE, TENSORBOARD_DIR


def append_event(run_dir: Path, event: dict[str, Any]) -> None:
    """Append one event line, stamped with ``time`` (Unix seconds), and sync it: a reader sees
    whole lines, and a crash loses none."""
    line = json.dumps(_finite({**event, "time": round(time.time(), 3)}), separators=(",", ":")) + "\n"
    with open(run_dir / PROGRESS_FILE, "a", encoding="utf-8") as fh:
        fh.write(line)
        fh.flush()
        os.fsync(fh.fileno())


def read_events(run_dir: Path) -> list[dict[str, Any]]:
    """Every complete event of the run, oldest first."""
    path = run_dir / PROGRESS_FILE
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def _finite(value: Any) -> Any:
    # JSON has no NaN: a diverged loss or an empty region's EPE is written as null.
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


class Board:
    """TensorBoard scalars and images; a resumed run drops what was logged after its checkpoint."""

    def __init__(self, run_dir: Path, start_step: int) -> None:
        self.writer = SummaryWriter(str(run_dir / TENSORBOARD_DIR), purge_step=start_step or None)

    def scalars(self, step: int, prefix: str, values: dict[str, float]) -> None:
        for name, value in values.items():
            if math.isfinite(value):
                self.writer.add_scalar(f"{prefix}/{name}", value, step)

    def image(self, step: int, tag: str, rgb: Any) -> None:
        """``rgb``: uint8 H×W×3."""
        self.writer.add_image(tag, rgb, step, dataformats="HWC")

    def flush(self) -> None:
        self.writer.flush()

    def close(self) -> None:
        self.writer.close()
