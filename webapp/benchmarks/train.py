"""Training speed of the ``lite`` preset at its crop: samples/s with 1 and 2 processes
(``python -m model.train`` and ``torchrun --standalone --nproc-per-node 2``), on synthetic frames
written in the SceneFlow layout."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from dataset.formats import write_pfm, write_rgb
from dataset.synthetic import render_video
from model.presets import load_preset
from model.train.events import read_events

FRAMES = 4


def run_train_bench(steps: int = 8, processes: tuple[int, ...] = (1, 2)) -> dict[str, Any]:
    """Samples/s over ``steps`` timed steps after a first untimed one (start-up), per process count."""
    config = load_preset("lite")
    height, width = config.train.crop
    batch = config.train.batch_size
    out: dict[str, Any] = {"lite_crop": [height, width], "batch_size": batch, "steps": steps}
    with tempfile.TemporaryDirectory(prefix="bench-train-") as tmp:
        root = Path(tmp)
        names = _write_frames(root / "data", height, width)
        for nproc in processes:
            run_dir = root / f"run{nproc}"
            _write_run(run_dir, root / "data", names, steps + 1)
            command = [sys.executable, "-m", "model.train", str(run_dir)] if nproc == 1 else [
                str(Path(sys.executable).with_name("torchrun")), "--standalone", f"--nproc-per-node={nproc}",
                "-m", "model.train", str(run_dir)]
            result = subprocess.run(command, capture_output=True, text=True, check=False)
            if result.returncode != 0:
                raise RuntimeError(f"training with {nproc} process(es) failed: {result.stderr.strip()[-2000:]}")
            out[f"train_{nproc}proc_samples_per_s"] = round(_rate(run_dir, batch), 3)
    return out


def _write_frames(root: Path, height: int, width: int) -> list[str]:
    """``FRAMES`` synthetic frames at the crop's size; their SceneFlow sample names."""
    video = render_video(0, n_frames=FRAMES, width=width, height=height)
    names = []
    for frame in video.frames:
        stem = f"{frame.index:04d}"
        write_rgb(root / "frames_cleanpass" / "bench" / "left" / f"{stem}.png", frame.left)
        write_rgb(root / "frames_cleanpass" / "bench" / "right" / f"{stem}.png", frame.right)
        write_pfm(root / "disparity" / "bench" / "left" / f"{stem}.pfm", frame.disparity)
        names.append(f"frames_cleanpass/bench/left/{stem}")
    return names


def _write_run(run_dir: Path, data: Path, names: list[str], steps: int) -> None:
    # Validation off and one checkpoint at the end: only training steps are timed.
    config = load_preset("lite", {"steps": steps, "checkpoint_every": steps, "val_every": steps})
    run_dir.mkdir(parents=True)
    (run_dir / "run.json").write_text(json.dumps({
        "config": config.to_dict(), "dataset": None, "media_root": None, "init_checkpoint": None, "device": "cpu",
        "splits": {"train": names, "val": [], "test": []}, "data": {"format": "sceneflow", "root": str(data)}}))


def _rate(run_dir: Path, batch: int) -> float:
    """Samples/s from the end of step 1 to the end of the last step (both always have an event)."""
    steps = [e for e in read_events(run_dir) if e["event"] == "step"]
    first, last = steps[0], steps[-1]
    return batch * (last["step"] - first["step"]) / (last["time"] - first["time"])
