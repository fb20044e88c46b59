"""The generation job: an annotated frame becomes a stereo training sample.

Monocular disparity → plane rectification of every illusion/support pair → right-view synthesis
(scale search, forward warp, inpainting) → QA figures (plane fits, holes, SGBM self-consistency)
→ a :class:`Sample` with its outputs in the media store (names in ``dataset.samples``).
Re-running for the same annotation version replaces that sample; the annotation is never touched.
"""

from __future__ import annotations

import io
import time
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import select

from annotation.inpaint import InpainterError
from core.formats import rle_to_mask
from core.geometry import (
    GeometryError,
    RegionMasks,
    psnr,
    rectify_disparity,
    stereo_consistency,
    synthesize_right_view,
)
from dataset.db import transaction
from dataset.finite import finite_json
from dataset.imported import depth_model_dir
from dataset.media import MediaStore
from dataset.samples import load_output, mask_name, store_outputs
from dataset.services.errors import Conflict, InvalidInput, NotFound
from dataset.services.frames import update_frame
from dataset.services.inpaint import hole_filler
from dataset.services.jobs import JobContext
from dataset.settings import Settings
from dataset.tables import Annotation, Frame, FrameState, RegionKind, Sample, SampleState, Video, utcnow
from dataset.version import code_version

GENERATABLE = (FrameState.annotated, FrameState.generated, FrameState.accepted)


class GenerationError(InvalidInput):
    """A frame that cannot become a sample; the message says why and what to do."""


@dataclass(frozen=True)
class MonoDisparity:
    """Where the generation's disparity comes from. ``scale`` is fixed when it is already in pixels."""

    disparity: np.ndarray  # float32 HxW, larger = nearer
    provenance: dict[str, Any]
    scale: float | None = None


@lru_cache(maxsize=2)
def _depth_model(model_path: str, device: str) -> Any:
    # One model per process: Depth Anything loads once per worker.
    from annotation.depth import make_depth_backend

    return make_depth_backend("depth-anything-v2", model_path=Path(model_path), device=device)


def mono_disparity(settings: Settings, media: MediaStore, frame: Frame, video: Video, left: np.ndarray) -> MonoDisparity:
    """The frame's monocular disparity, by the first source that applies:

    an external reconstruction (px, scale fixed to 1) → Depth Anything V2 when configured (cached
    per frame and model) → a disparity imported with the frame → a synthetic scene's recorded
    mono-fooled disparity (labelled simulated).
    """
    assets = frame.assets
    if "reconstruction_disparity" in assets:
        return MonoDisparity(load_output(media, assets["reconstruction_disparity"], "disparity"),
                             {"depth_backend": "reconstruction", "simulated": False, "units": "px"}, scale=1.0)
    if settings.depth_backend == "depth-anything-v2":
        if settings.depth_model_path is None:
            raise GenerationError("depth_backend is depth-anything-v2 but depth_model_path is not set")
        # depth_model_path may name an import (imported:NAME): the same directory `depth --checkpoint` runs
        model = _depth_model(str(depth_model_dir(settings)), settings.device)
        cache_key = f"mono:{model.model_id}"
        if cache_key in assets:
            disparity = load_output(media, assets[cache_key], "disparity_mono")
        else:
            disparity = model.estimate(left)
        return MonoDisparity(disparity, {"depth_backend": "depth-anything-v2", "depth_model_id": model.model_id,
                                         "simulated": False, "units": "relative", "cache_key": cache_key})
    if "precomputed_disparity" in assets:
        return MonoDisparity(load_output(media, assets["precomputed_disparity"], "disparity_mono"),
                             {"depth_backend": "precomputed", "simulated": False, "units": "imported"})
    if "mono_disparity" in assets and video.meta.get("synthetic"):
        disparity = np.load(io.BytesIO(media.read_bytes(assets["mono_disparity"])))
        return MonoDisparity(disparity.astype(np.float32),
                             {"depth_backend": "synthetic", "simulated": True, "units": "relative",
                              "note": "a synthetic scene's simulated monocular estimate (relative, coarse, fooled "
                                      "by pictures and partly by mirrors), not a model's"})
    raise GenerationError(f"frame {frame.id} has no monocular disparity: set depth_backend = 'depth-anything-v2' "
                          "with depth_model_path, or import precomputed disparities with the frames "
                          "(illusion-studio ingest --mono DIR); then retry this job")


def generate_job(ctx: JobContext) -> dict[str, Any]:
    """Job ``generate``: params ``frame_id``, ``annotation_version``."""
    started = time.process_time()
    settings, media = ctx.settings, ctx.media
    with ctx.sessions() as s:
        frame = s.get(Frame, ctx.params["frame_id"])
        if frame is None:
            raise NotFound(f"no frame {ctx.params['frame_id']}")
        if frame.state not in GENERATABLE:
            raise Conflict(f"frame {frame.id} is {frame.state.value}; only annotated frames are generated")
        video = s.get(Video, frame.video_id)
        ann = s.scalar(select(Annotation).where(Annotation.frame_id == frame.id))
        if ann is None or not ann.submitted:
            raise GenerationError(f"frame {frame.id} has no submitted annotation")
        version = ann.version
        if ctx.params.get("annotation_version") not in (None, version):
            ctx.log(f"annotation moved on to version {version} since this job was queued; generating that")
        regions = [(r.pair, r.kind, r.mask_rle) for r in ann.regions]
        illusion_type = ann.illusion_type.value if ann.illusion_type else None
        # Mask files are numbered from 00 in the pairs' order, whatever numbers the page gave them.
        order = {pair: n for n, pair in enumerate(sorted({r.pair for r in ann.regions}))}
        # A pair's own type (a frame can hold a picture and a mirror), else the annotation's.
        pair_types = {mask_name("illusion", order[r.pair]): (r.illusion_type.value if r.illusion_type else illusion_type)
                      for r in ann.regions if r.kind == RegionKind.illusion}
    left = load_output(media, frame.media_key, "left")
    ctx.progress(0.1, "monocular disparity")
    mono = mono_disparity(settings, media, frame, video, left)
    pairs = _pairs(regions, (frame.height, frame.width))
    ctx.progress(0.3, f"rectifying {len(pairs)} pair(s)")
    try:
        rect = rectify_disparity(mono.disparity, [p for _, p in pairs], guide=left,
                                 threshold=settings.plane_threshold, hypotheses=settings.plane_hypotheses,
                                 seed=frame.id)
        ctx.progress(0.5, "synthesizing the right view")
        view = synthesize_right_view(left, rect.disparity, scale=mono.scale, tau=settings.right_view_tau,
                                     inpaint=hole_filler(settings.inpaint_backend, settings.lama_model_path))
    except (GeometryError, InpainterError) as exc:
        raise GenerationError(f"frame {frame.id}: {exc}") from None
    disparity = (view.scale * rect.disparity).astype(np.float32)
    ctx.progress(0.7, "quality checks")
    check = stereo_consistency(left, view.image, disparity, ignore=view.holes)
    qa = _qa(settings, rect.reports, view, check, [pair for pair, _ in pairs])
    if "reconstruction_right" in frame.assets:
        # The reconstruction's own rendering should agree with our warp wherever the pairs left the
        # disparity alone; a low figure means the imported disparity and rendering disagree.
        rendered = load_output(media, frame.assets["reconstruction_right"], "right")
        untouched = ~view.holes & ~np.any([p.illusion for _, p in pairs], axis=0)
        qa["reconstruction_right_psnr_db"] = finite_json(psnr(view.image, rendered, untouched))
    outputs: dict[str, Any] = {
        "left": left, "right": view.image, "disparity": disparity, "disparity_rect": rect.disparity,
        "disparity_mono": mono.disparity, "holes": view.holes,
        "masks": {mask_name(kind, order[pair]): mask for pair, p in pairs
                  for kind, mask in (("illusion", p.illusion), ("support", p.support)) if mask is not None},
    }
    files = store_outputs(media, outputs)
    params = finite_json({"scale": view.scale, "tau": settings.right_view_tau, "valid_ratio": view.valid_ratio,
              "plane_threshold": settings.plane_threshold, "plane_hypotheses": settings.plane_hypotheses,
              "inpaint": settings.inpaint_backend, "seed": frame.id})
    provenance = {**mono.provenance, "source": "reconstruction" if mono.provenance["depth_backend"] == "reconstruction"
                  else "synthesized", "illusion_type": illusion_type,
                  "pair_types": {name: t for name, t in pair_types.items() if t}, "frame_id": frame.id, "video": video.name,
                  "annotation_version": version, "code_version": code_version(), "generated_at": utcnow().isoformat() + "Z"}
    qa["cpu_s"] = round(time.process_time() - started, 3)
    with transaction(ctx.sessions) as s:
        sample = s.scalar(select(Sample).where(Sample.frame_id == frame.id, Sample.annotation_version == version))
        if sample is None:
            sample = Sample(frame_id=frame.id, annotation_version=version)
            s.add(sample)
        sample.files, sample.params, sample.provenance, sample.qa = files, params, provenance, qa
        sample.state, sample.flagged = SampleState.generated, bool(qa["flags"])
        current = s.get(Frame, frame.id)
        if "cache_key" in mono.provenance:  # keep the model's estimate for the next run
            current.assets = {**current.assets, mono.provenance["cache_key"]: files["disparity_mono"]}
        if current.state != FrameState.generated:  # a regenerated accepted sample needs a new look
            update_frame(s, current, state=FrameState.generated)
        s.flush()
        sample_id = sample.id
    ctx.log(f"sample {sample_id}: scale {view.scale:.3f}, holes {qa['hole_fraction']:.1%}, SGBM EPE {check.epe:.2f} px"
            + (f"; flagged: {', '.join(qa['flags'])}" if qa["flags"] else ""))
    return {"sample_id": sample_id, "frame_id": frame.id, "flags": qa["flags"], "cpu_s": qa["cpu_s"]}


def _pairs(regions: list[tuple[int, RegionKind, dict[str, Any]]], shape: tuple[int, int]) -> list[tuple[int, RegionMasks]]:
    masks: dict[int, dict[RegionKind, np.ndarray]] = {}
    for pair, kind, rle in regions:
        masks.setdefault(pair, {})[kind] = rle_to_mask(rle, shape)
    out = []
    for pair in sorted(masks):
        if RegionKind.illusion not in masks[pair]:
            raise GenerationError(f"pair {pair} has no illusion region")
        out.append((pair, RegionMasks(masks[pair][RegionKind.illusion], masks[pair].get(RegionKind.support))))
    return out


def _qa(settings: Settings, reports: list[Any], view: Any, check: Any, pair_ids: list[int]) -> dict[str, Any]:
    pairs = [{**r.as_dict(), "pair": pair} for r, pair in zip(reports, pair_ids, strict=True)]
    for p in pairs:
        p.pop("index", None)
    hole_fraction = float(view.holes.mean())
    flags = []
    if hole_fraction > settings.qa_max_hole_fraction:
        flags.append(f"holes {hole_fraction:.0%} > {settings.qa_max_hole_fraction:.0%}")
    if not np.isfinite(check.epe) or check.epe > settings.qa_max_stereo_epe:
        flags.append(f"SGBM EPE {check.epe:.2f} px > {settings.qa_max_stereo_epe:g}")
    # Flags are read by people: pairs counted from 1 in id order, as the Annotate page counts its planes
    # (the stored ids, in "pair", may start at 0).
    for number, p in enumerate(pairs, 1):
        if p["status"] != "rectified":
            flags.append(f"pair {number} {p['status']}: {p['reason']}")
        elif p["inlier_ratio"] is not None and p["inlier_ratio"] < settings.qa_min_inlier_ratio:
            flags.append(f"pair {number} inlier ratio {p['inlier_ratio']:.2f} < {settings.qa_min_inlier_ratio:g}")
    return finite_json({"pairs": pairs, "scale": view.scale, "hole_fraction": hole_fraction, "stereo_epe": check.epe,
                        "stereo_bad2": check.bad2, "stereo_coverage": check.coverage, "flags": flags})
