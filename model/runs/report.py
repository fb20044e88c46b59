"""An evaluation's report folder: ``report.json``, ``per_sample.csv``, ``index.html`` (the paper-style
table, sortable per-sample metrics, pictures of the worst and best samples) and the predictions as
PFM (and KITTI PNG on request) in the dataset's own layout."""

from __future__ import annotations

import csv
import html
import io
import json
import math
import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from core.atomic import atomic_write_bytes
from core.formats import encode_pfm, write_kitti_disparity, write_png
from dataset.preview.images import colorize, colorize_error, value_range
from dataset.readers import StereoSample
from model.methods import prediction_path

TABLE_METRICS = ("epe", "bad1", "bad2", "bad3", "bad5")
DEPTH_METRICS = ("abs_rel", "rmse", "log10", "delta1", "delta2", "delta3")
ERROR_MAP_MAX_PX = 8.0  # error maps saturate here: a few pixels is where illusions show
ASSET = Path(__file__).resolve().parent / "report_assets" / "report.js"
PICTURE_KINDS = {"left": "left image", "gt": "ground truth"}


class PredictionWriter:
    """Writes each prediction as ``predictions/<method>/<sample path>.pfm`` (and ``.png`` in KITTI's
    uint16 ×256 encoding when asked), and keeps the pictures of the samples the report shows.

    ``labels``: sample name → how the app names it (``synthetic-0000 · frame #4``) for the samples
    of the database, whose names (``video_1/frame_000000``) mean nothing to a person."""

    def __init__(self, out_dir: Path, *, kitti_png: bool = False) -> None:
        self.out_dir, self.kitti_png = out_dir, kitti_png
        self.labels: dict[str, str] = {}

    def __call__(self, method: str, sample: StereoSample, pred: np.ndarray) -> None:
        label = sample_label(sample.meta)
        if label:
            self.labels[sample.name] = label
        path = prediction_path(self.out_dir / "predictions" / method, sample)
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, encode_pfm(np.asarray(pred, np.float32)))
        if self.kitti_png:
            write_kitti_disparity(path.with_suffix(".png"), np.nan_to_num(pred))


def sample_label(meta: dict[str, Any]) -> str | None:
    """A database sample's name as the app's pages say it (``labels.js`` framePlace without the
    time): its video by name, its frame by id; None for a folder's sample."""
    if meta.get("frame_id") is None or meta.get("video_name") is None:
        return None
    return f"{meta['video_name']} · frame #{meta['frame_id']}"


def picture_caption(path: str) -> str:
    """What a picture of :func:`write_pictures` shows, from its file name: ``…__sgbm_error.png`` →
    ``sgbm error (0–8 px)``."""
    kind = Path(path).name.rsplit("__", 1)[-1].removesuffix(".png")
    if kind in PICTURE_KINDS:
        return PICTURE_KINDS[kind]
    if kind.endswith("_error"):
        return f"{kind.removesuffix('_error')} error (0–{ERROR_MAP_MAX_PX:g} px)"
    return f"{kind} prediction"


def ranked_samples(report: dict[str, Any], method: str, region: str = "all", count: int = 3) -> tuple[list[str], list[str]]:
    """The worst samples of ``method`` by EPE on ``region`` (the worst first) and the best (the best
    first), at most ``count`` of each. No sample is in both: of n < 2·count samples the worse ⌈n/2⌉
    are the worst and the others the best (none for a single sample)."""
    rows = [(r["regions"].get(region, {}).get("epe", math.nan), r["sample"]) for r in report["methods"][method]["per_sample"]]
    ranked = [s for _, s in sorted(((e, s) for e, s in rows if math.isfinite(e)), reverse=True)]
    worst = min(count, math.ceil(len(ranked) / 2))
    return ranked[:worst], ranked[worst:][::-1][:count]


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


def write_report(out_dir: Path, report: dict[str, Any], pictures: dict[str, list[str]] | None = None,
                 labels: dict[str, str] | None = None) -> None:
    """``report.json``, ``per_sample.csv`` and ``index.html`` (+ its script) in ``out_dir``;
    ``labels`` (:attr:`PredictionWriter.labels`) name the database's samples in the page."""
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out_dir / "report.json", json.dumps(report, indent=1, default=_json_default).encode())
    atomic_write_bytes(out_dir / "per_sample.csv", per_sample_csv(report).encode())
    atomic_write_bytes(out_dir / "index.html", report_html(report, pictures or {}, labels or {}).encode())
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


def _regions_and_metrics(methods: dict[str, Any]) -> tuple[list[str], tuple[str, ...]]:
    regions: list[str] = []
    for data in methods.values():
        regions += [r for r in data["regions"] if r not in regions]
    has_depth = any("abs_rel" in f for d in methods.values() for f in d["regions"].values())
    return regions, TABLE_METRICS + (DEPTH_METRICS if has_depth else ())


def report_html(report: dict[str, Any], pictures: dict[str, list[str]], labels: dict[str, str] | None = None) -> str:
    """A standalone page: per region, the methods as rows and the metrics as columns (EPE in px,
    bad-x in %), so that it fits a laptop's width whatever the regions; the sortable per-sample
    EPE; the worst and best samples' pictures, each captioned."""
    labels = labels or {}
    methods = report["methods"]
    regions, metrics = _regions_and_metrics(methods)
    esc = html.escape
    body = "".join(
        f'<tbody data-region="{esc(r)}">' + "".join(
            "<tr>" + (f'<th rowspan="{len(methods)}" scope="rowgroup">{esc(r)}</th>' if i == 0 else "")
            + f"<th>{esc(name)}</th>"
            + "".join(f"<td>{_fmt(data['regions'].get(r, {}).get(m))}</td>" for m in metrics) + "</tr>"
            for i, (name, data) in enumerate(methods.items())) + "</tbody>"
        for r in regions)
    sample_rows = "".join(
        f"<tr><td>{esc(name)}</td><td>{esc(labels.get(row['sample'], row['sample']))}</td>"
        + "".join(f'<td data-v="{_value(row["regions"].get(r, {}).get("epe"))}">{_fmt(row["regions"].get(r, {}).get("epe"))}</td>'
                  for r in regions) + "</tr>"
        for name, data in methods.items() for row in data["per_sample"])
    failed = "".join(f"<li>{esc(labels.get(f['sample'], f['sample']))} {esc(f['method'])}: {esc(f['reason'])}</li>"
                     for f in report.get("failed", []))
    figures = "".join(
        f"<section class=\"pictures\"><h3>{esc(_picture_title(title, labels))}</h3>"
        + "".join(f'<figure><img src="{esc(p)}" alt="{esc(picture_caption(p))}" loading="lazy">'
                  f"<figcaption>{esc(picture_caption(p))}</figcaption></figure>" for p in paths)
        + "</section>" for title, paths in pictures.items())
    facts = "".join(f"<dt>{esc(k)}</dt><dd>{esc(_shown(v))}</dd>" for k, v in report.items()
                    if k not in ("methods", "failed"))
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>Evaluation · {esc(_shown(report.get('dataset', '')))}</title>
<style>body{{font:14px system-ui,sans-serif;margin:1.5rem;max-width:100%}}table{{border-collapse:collapse;margin:1rem 0}}
td,th{{border:1px solid #ccc;padding:.25rem .5rem;text-align:right}}th{{background:#f4f4f4}}
dl{{display:grid;grid-template-columns:max-content 1fr;gap:.1rem 1rem}}dd{{margin:0}}
section.pictures{{display:grid;grid-template-columns:repeat(auto-fill,minmax(170px,1fr));gap:.3rem;margin:1rem 0}}
section.pictures h3{{grid-column:1/-1;margin:.3rem 0}}section.pictures figure{{margin:0}}section.pictures img{{width:100%}}
#per-sample td:nth-child(-n+2){{text-align:left}}
figcaption{{font-size:12px;color:#555}}table.sortable th{{cursor:pointer}}
table.sortable th[data-order="asc"]::after{{content:" ▲"}}
table.sortable th[data-order="desc"]::after{{content:" ▼"}}</style></head>
<body><h1>Evaluation</h1>
<dl>{facts}</dl>
<p>EPE in pixels, bad-x and δ in percent; the mean over samples (pooled figures in report.json).</p>
<table class="paper"><thead><tr><th>region</th><th>method</th>{''.join(f"<th>{m}</th>" for m in metrics)}</tr></thead>
{body}</table>
<h2>Samples (EPE, px)</h2>
<p>Click a column to sort by it: the first click puts the worst first.</p>
<table id="per-sample" class="sortable"><thead><tr><th>method</th><th>sample</th>
{''.join(f'<th>{esc(r)}</th>' for r in regions)}</tr></thead><tbody>{sample_rows}</tbody></table>
<h2>Failed ({len(report.get('failed', []))})</h2><ul>{failed}</ul>
<h2>Worst and best samples</h2>{figures}
<script src="{ASSET.name}" defer></script>
</body></html>"""


def _value(value: Any) -> str:
    """A sortable cell's number (empty where there is none)."""
    return "" if value is None or (isinstance(value, float) and not math.isfinite(value)) else str(value)


def _picture_title(title: str, labels: dict[str, str]) -> str:
    """``worst: video_1/frame_000000`` with the sample named as the app names it."""
    rank, _, name = title.partition(": ")
    return f"{rank}: {labels.get(name, name)}" if name else title


# An absolute path's folders (not a URL's, nor a part of another path): the page keeps only the name.
_FOLDERS = re.compile(r"(?<![\w:/.~>-])/(?:[\w.+@-]+/)+(?=[\w.+@-])")


def _shown(value: Any) -> str:
    """A report fact as text (a mapping as ``key: value, …``), a server folder cut to ``…/``: the
    page is a file one may pass around, outside the app's answers."""
    if isinstance(value, dict):
        return ", ".join(f"{k}: {_shown(v)}" for k, v in value.items() if v is not None)
    return _FOLDERS.sub("…/", str(value))
