"""An evaluation's report folder: ``report.json``, ``per_sample.csv``, ``index.html`` (the paper-style
table, sortable per-sample metrics, pictures of the worst and best samples) and the predictions as
PFM (and KITTI PNG on request) in the dataset's own layout."""

from __future__ import annotations

import csv
import html
import io
import json
import math
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from dataset.atomic import atomic_write_bytes
from dataset.formats import encode_pfm, write_kitti_disparity, write_png
from dataset.preview.images import colorize, colorize_error, value_range
from dataset.readers import StereoSample

TABLE_METRICS = ("epe", "bad1", "bad2", "bad3", "bad5")
DEPTH_METRICS = ("abs_rel", "rmse", "log10", "delta1", "delta2", "delta3")
ERROR_MAP_MAX_PX = 8.0  # error maps saturate here: a few pixels is where illusions show
ASSET = Path(__file__).resolve().parent / "report_assets" / "report.js"


class PredictionWriter:
    """Writes each prediction as ``predictions/<method>/<sample path>.pfm`` (and ``.png`` in KITTI's
    uint16 ×256 encoding when asked), and keeps the pictures of the samples the report shows."""

    def __init__(self, out_dir: Path, *, kitti_png: bool = False) -> None:
        self.out_dir, self.kitti_png = out_dir, kitti_png

    def __call__(self, method: str, sample: StereoSample, pred: np.ndarray) -> None:
        rel = Path(str(sample.meta.get("left") or sample.name)).with_suffix(".pfm")
        path = self.out_dir / "predictions" / method / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, encode_pfm(np.asarray(pred, np.float32)))
        if self.kitti_png:
            write_kitti_disparity(path.with_suffix(".png"), np.nan_to_num(pred))


def ranked_samples(report: dict[str, Any], method: str, region: str = "all", count: int = 3) -> tuple[list[str], list[str]]:
    """The ``count`` worst and best samples of ``method`` by EPE on ``region``."""
    rows = [(r["regions"].get(region, {}).get("epe", math.nan), r["sample"]) for r in report["methods"][method]["per_sample"]]
    rows = sorted((e, s) for e, s in rows if math.isfinite(e))
    best = [s for _, s in rows[:count]]
    worst = [s for _, s in reversed(rows[-count:])]
    return worst, best


def write_pictures(out_dir: Path, sample: StereoSample, predictions: dict[str, np.ndarray]) -> list[str]:
    """PNGs of one sample under ``pictures/``: left, ground truth and, per method, the prediction and
    its error map (colours shared across methods). Returns their paths relative to ``out_dir``."""
    stem = sample.name.replace("/", "__")
    folder = out_dir / "pictures"
    folder.mkdir(parents=True, exist_ok=True)
    lo, hi = value_range(sample.disparity, *predictions.values())
    images = {"left": sample.left, "gt": colorize(sample.disparity, lo, hi)}
    for method, pred in predictions.items():
        images[f"{method}"] = colorize(pred, lo, hi)
        err = np.abs(pred - sample.disparity)
        images[f"{method}_error"] = colorize_error(err, ERROR_MAP_MAX_PX)
    paths = []
    for name, image in images.items():
        path = folder / f"{stem}__{name}.png"
        write_png(path, image)
        paths.append(str(path.relative_to(out_dir)))
    return paths


def write_report(out_dir: Path, report: dict[str, Any], pictures: dict[str, list[str]] | None = None) -> None:
    """``report.json``, ``per_sample.csv`` and ``index.html`` (+ its script) in ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out_dir / "report.json", json.dumps(report, indent=1, default=_json_default).encode())
    atomic_write_bytes(out_dir / "per_sample.csv", per_sample_csv(report).encode())
    atomic_write_bytes(out_dir / "index.html", report_html(report, pictures or {}).encode())
    shutil.copyfile(ASSET, out_dir / ASSET.name)


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def per_sample_csv(report: dict[str, Any]) -> str:
    """One row per (method, sample, region) with every metric as a column."""
    keys: list[str] = []
    rows = []
    for method, data in report["methods"].items():
        for row in data["per_sample"]:
            for region, figures in row["regions"].items():
                keys += [k for k in figures if k not in keys]
                rows.append({"method": method, "sample": row["sample"], "region": region, **figures})
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=["method", "sample", "region", *keys])
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def _fmt(value: Any) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return f"{value:.2f}" if isinstance(value, float) else str(value)


def report_html(report: dict[str, Any], pictures: dict[str, list[str]]) -> str:
    """A standalone page: methods as rows, regions as column groups (EPE in px, bad-x in %)."""
    methods = report["methods"]
    regions: list[str] = []
    for data in methods.values():
        regions += [r for r in data["regions"] if r not in regions]
    has_depth = any("abs_rel" in f for d in methods.values() for f in d["regions"].values())
    metrics = TABLE_METRICS + (DEPTH_METRICS if has_depth else ())
    head1 = "".join(f'<th colspan="{len(metrics)}">{html.escape(r)}</th>' for r in regions)
    head2 = "".join(f"<th>{m}</th>" for _ in regions for m in metrics)
    body = "".join(
        f"<tr><th>{html.escape(name)}</th>"
        + "".join(f"<td>{_fmt(data['regions'].get(r, {}).get(m))}</td>" for r in regions for m in metrics) + "</tr>"
        for name, data in methods.items())
    sample_rows = "".join(
        f"<tr><td>{html.escape(name)}</td><td>{html.escape(row['sample'])}</td>"
        + "".join(f'<td data-v="{row["regions"].get(r, {}).get("epe", "")}">{_fmt(row["regions"].get(r, {}).get("epe"))}</td>'
                  for r in regions) + "</tr>"
        for name, data in methods.items() for row in data["per_sample"])
    failed = "".join(f"<li>{html.escape(f['sample'])} {html.escape(f['method'])}: {html.escape(f['reason'])}</li>"
                     for f in report.get("failed", []))
    figures = "".join(
        f"<figure><figcaption>{html.escape(label)}</figcaption>"
        + "".join(f'<img src="{html.escape(p)}" alt="{html.escape(Path(p).stem)}" loading="lazy">' for p in paths)
        + "</figure>" for label, paths in pictures.items())
    meta = {k: v for k, v in report.items() if k not in ("methods", "failed")}
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>Evaluation · {html.escape(str(report.get('dataset', '')))}</title>
<style>body{{font:14px system-ui,sans-serif;margin:1.5rem}}table{{border-collapse:collapse;margin:1rem 0}}
td,th{{border:1px solid #ccc;padding:.25rem .5rem;text-align:right}}th{{background:#f4f4f4}}
figure{{margin:1rem 0}}figure img{{max-width:24%;margin:.1rem}}th.sortable{{cursor:pointer}}</style></head>
<body><h1>Evaluation</h1>
<p>{html.escape(json.dumps(meta, default=str))}</p>
<p>EPE in pixels, bad-x and δ in percent; the mean over samples (pooled figures in report.json).</p>
<table class="paper"><thead><tr><th rowspan="2">method</th>{head1}</tr><tr>{head2}</tr></thead><tbody>{body}</tbody></table>
<h2>Samples (EPE)</h2>
<table id="per-sample" class="sortable"><thead><tr><th class="sortable">method</th><th class="sortable">sample</th>
{''.join(f'<th class="sortable">{html.escape(r)}</th>' for r in regions)}</tr></thead><tbody>{sample_rows}</tbody></table>
<h2>Failed ({len(report.get('failed', []))})</h2><ul>{failed}</ul>
<h2>Worst and best samples</h2>{figures}
<script type="module" src="{ASSET.name}"></script>
</body></html>"""
