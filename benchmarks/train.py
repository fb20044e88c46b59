"""Training speed of the ``lite`` preset at its crop: samples/s with 1 and 2 processes
(``python -m model.train`` and ``torchrun --standalone --nproc-per-node 2``, gloo DDP), on a pinned
dataset version of accepted synthetic samples made the product's way."""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.workspace import synthetic_version, write_train_run
from model.presets import load_preset
from model.train.events import read_events


def run_train_bench(steps: int = 8, processes: tuple[int, ...] = (1, 2)) -> dict[str, Any]:
    """Samples/s over ``steps`` timed steps after a first untimed one (start-up), per process count."""
    config = load_preset("lite")
    height, width = config.train.crop
    out: dict[str, Any] = {"lite_crop": [height, width], "batch_size": config.train.batch_size, "steps": steps}
    with tempfile.TemporaryDirectory(prefix="bench-train-") as tmp:
        root = Path(tmp)
        # Frames at the crop's size, so the crop sees whole frames (scale augmentation aside).
        version, media_root = synthetic_version(root, width=width, height=height, n_frames=3)
        out["samples"] = len(version["items"])
        # Validation off and one checkpoint at the end: only training steps are timed.
        timed = load_preset("lite", {"steps": steps + 1, "checkpoint_every": steps + 1, "val_every": steps + 1})
        for nproc in processes:
            run_dir = root / f"run{nproc}"
            write_train_run(run_dir, timed, version, media_root)
            command = [sys.executable, "-m", "model.train", str(run_dir)] if nproc == 1 else [
                str(Path(sys.executable).with_name("torchrun")), "--standalone", f"--nproc-per-node={nproc}",
                "-m", "model.train", str(run_dir)]
            result = subprocess.run(command, capture_output=True, text=True, check=False)
            if result.returncode != 0:
                raise RuntimeError(f"training with {nproc} process(es) failed: {result.stderr.strip()[-2000:]}")
            out[f"train_{nproc}proc_samples_per_s"] = round(_rate(run_dir, config.train.batch_size), 3)
    return out


def _rate(run_dir: Path, batch: int) -> float:
    """Samples/s from the end of step 1 to the end of the last step (both always have an event)."""
    steps = [e for e in read_events(run_dir) if e["event"] == "step"]
    first, last = steps[0], steps[-1]
    return batch * (last["step"] - first["step"]) / (last["time"] - first["time"])
