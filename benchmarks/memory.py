"""Peak memory of the real trainer (``python -m model.train``, one rank) at several crops and GRU
iterations, the least-squares fit of ``model.runs.capacity``'s memory model to them, and that model's
estimate beside each measurement: how ``MEMORY_MB`` is calibrated for a (preset, device)."""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.workspace import synthetic_version, write_train_run
from model.presets import load_preset
from model.runs.capacity import coefficients

# (H, W, iterations): spans the lite preset's crop (192x320, 7) to four times its work per sample.
POINTS = ((192, 320, 4), (192, 320, 7), (320, 512, 7), (384, 640, 7), (384, 640, 14))
STEPS = 3
# The trainer's own peak resident set (VmHWM), read by the child itself as it ends.
_CHILD = """
import runpy, sys
sys.argv = ["model.train", sys.argv[1]]
try:
    runpy.run_module("model.train", run_name="__main__")
except SystemExit:
    pass
finally:
    peak = next(line for line in open("/proc/self/status") if line.startswith("VmHWM"))
    print("PEAK_KB", int(peak.split()[1]), flush=True)
"""


def run_memory_bench(preset: str = "lite", points: tuple[tuple[int, int, int], ...] = POINTS) -> dict[str, Any]:
    """Measured peak MB per point, the fitted (base, MB per megapixel·iteration), and the estimate
    that ``model.runs.capacity`` makes today for each point."""
    height = max(p[0] for p in points)
    width = max(p[1] for p in points)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-memory-") as tmp:
        root = Path(tmp)
        version, media_root = synthetic_version(root, width=width, height=height, n_frames=2)
        base, per_pixel = coefficients(preset, "cpu")
        for i, (h, w, iters) in enumerate(points):
            config = load_preset(preset, {"steps": STEPS, "checkpoint_every": STEPS, "val_every": STEPS,
                                          "crop": (h, w), "train_iters": iters, "batch_size": 1,
                                          "scale": (0.0, 0.0)})
            run_dir = root / f"run{i}"
            write_train_run(run_dir, config, version, media_root)
            done = subprocess.run([sys.executable, "-c", _CHILD, str(run_dir)], capture_output=True, text=True,
                                  check=False)
            peak = [line for line in done.stdout.splitlines() if line.startswith("PEAK_KB")]
            if not peak:
                raise RuntimeError(f"trainer at {h}x{w}×{iters} printed no peak: {done.stderr.strip()[-1500:]}")
            megapixel_iters = h * w / 1e6 * iters
            rows.append({"crop": [h, w], "iters": iters, "peak_mb": round(int(peak[0].split()[1]) / 1024, 1),
                         "estimate_mb": round(base + per_pixel * megapixel_iters, 1),
                         "megapixel_iters": round(megapixel_iters, 4)})
    x = np.array([[1.0, r["megapixel_iters"]] for r in rows])
    y = np.array([r["peak_mb"] for r in rows])
    (fit_base, fit_per_pixel), *_ = np.linalg.lstsq(x, y, rcond=None)
    return {"preset": preset, "device": "cpu", "points": rows,
            "fit": {"base_mb": round(float(fit_base), 1), "mb_per_megapixel_iter": round(float(fit_per_pixel), 1)},
            "in_use": {"base_mb": base, "mb_per_megapixel_iter": per_pixel}}
