"""Plane rectification of illusion regions (paper §3.1 "Depth Generation").

For each illusion/support pair: fit a plane to the support region's (u, v, d) points, write the
plane's disparity into the illusion region, then smooth a band around the illusion's boundary
with a guided filter so the patch meets its surroundings without a seam.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Literal, Protocol

import cv2
import numpy as np

from core.geometry import checks
from core.geometry.errors import DegenerateSupportError, GeometryError, InputError
from core.geometry.filters import guided_filter
from core.geometry.plane import fit_plane_ransac


class UnreliableSupportError(GeometryError):
    """The support region is mostly covered by its illusion, so it cannot be trusted."""


class MaskPair(Protocol):
    """An illusion mask and the mask of the real surface it lies on (bool HxW each)."""

    @property
    def illusion(self) -> np.ndarray: ...

    @property
    def support(self) -> np.ndarray | None: ...


@dataclass(frozen=True)
class RegionMasks:
    """A plain :class:`MaskPair`; ``support=None`` (or empty) means "use a ring around it"."""

    illusion: np.ndarray
    support: np.ndarray | None = None


Status = Literal["rectified", "skipped", "unreliable"]


@dataclass(frozen=True)
class PairReport:
    """Quality figures of one pair. Disparity-valued figures are in input disparity units."""

    index: int
    status: Status
    reason: str | None
    illusion_px: int
    support_px: int
    support_source: Literal["mask", "ring"]
    overlap: float
    inlier_ratio: float | None = None
    residual: float | None = None
    plane: tuple[float, float, float, float] | None = None

    def as_dict(self) -> dict[str, object]:
        """JSON-ready figures."""
        return asdict(self)


@dataclass(frozen=True)
class Rectified:
    """``disparity``: float32 HxW, same units as the input; ``band``: bool HxW of smoothed pixels."""

    disparity: np.ndarray
    reports: list[PairReport]
    band: np.ndarray

    @property
    def rectified_count(self) -> int:
        return sum(r.status == "rectified" for r in self.reports)


def rectify_disparity(
    disparity: np.ndarray,
    regions: Sequence[MaskPair],
    *,
    guide: np.ndarray | None = None,
    threshold: float = 0.01,
    hypotheses: int = 1000,
    seed: int = 0,
    min_area: int = 100,
    max_overlap: float = 0.5,
    ring_thickness: int = 5,
    band_radius: int = 5,
    filter_eps: float = 1e-3,
    strict: bool = False,
) -> Rectified:
    """Replace each illusion region's disparity by the plane of its support region.

    ``disparity``: HxW, any positive-or-not units (pixels for stereo, arbitrary for monocular);
    NaN/inf pixels are ignored when fitting. ``regions``: illusion/support bool HxW mask pairs,
    applied in order. Following the authors: the disparity is min-max normalised to [0, 1] for
    fitting (``threshold`` is in those units; ``hypotheses`` RANSAC planes, ``seed``), masks
    under ``min_area`` px are skipped, a support more than ``max_overlap`` covered by its
    illusion is unreliable (not applied), a missing/empty support becomes a ring of
    ``ring_thickness`` px around the illusion. The band of ``band_radius`` px on both sides of
    each rectified illusion's boundary is blended (weight 1 at the boundary, 0 at the band's
    edge) with a guided-filtered copy (guide: ``guide``, a uint8 HxW(x3) image, else the
    rectified disparity itself; ``filter_eps`` in normalised units²); band pixels within
    2·``band_radius`` of a NaN are left as they are.

    Per-pair problems (tiny masks, degenerate or unreliable support) are reported in
    ``Rectified.reports`` with a reason, or raised when ``strict``. Raises :class:`InputError`
    for mismatched shapes/dtypes or an all-NaN disparity.
    """
    disp = checks.float_map(disparity, "disparity")
    shape = disp.shape
    if guide is not None:
        guide = checks.image(guide, "guide", shape)
    finite = np.isfinite(disp)
    low, high = float(disp[finite].min()), float(disp[finite].max())
    span = high - low if high > low else 1.0
    normalised = np.where(finite, (disp - low) / span, np.nan)

    fit = _FitSettings(threshold, hypotheses, seed, min_area, max_overlap, low, span)
    out = normalised.copy()
    rectified = np.zeros(shape, dtype=bool)
    reports = []
    for index, region in enumerate(regions):
        illusion = checks.mask(region.illusion, f"illusion mask #{index}", shape)
        support = checks.mask(region.support, f"support mask #{index}", shape)
        pair = _Pair(index, illusion, support, ring_thickness)
        try:
            report = _rectify_pair(pair, normalised, out, fit)
        except GeometryError as exc:
            if strict:
                raise
            status: Status = "unreliable" if isinstance(exc, UnreliableSupportError) else "skipped"
            report = pair.report(status, str(exc))
        else:
            rectified |= illusion
        reports.append(report)

    weight = _seam_weight(rectified, band_radius)
    # The filter's output at a pixel depends on inputs up to 2·radius away: band pixels that
    # close to a NaN keep their values rather than mixing in a made-up fill.
    weight[_dilate(~np.isfinite(out), 2 * band_radius)] = 0
    band = weight > 0
    if band.any():
        smooth_src = np.where(np.isfinite(out), out, 0.0)
        smoothed = guided_filter(guide if guide is not None else smooth_src, smooth_src, band_radius, filter_eps)
        out[band] += weight[band] * (smoothed[band] - out[band])
    return Rectified(disparity=(out * span + low).astype(np.float32), reports=reports, band=band)


class _Pair:
    """One pair's masks after the authors' substitution of a missing support by a ring."""

    def __init__(self, index: int, illusion: np.ndarray, support: np.ndarray, ring_thickness: int) -> None:
        self.index = index
        self.illusion = illusion
        self.source: Literal["mask", "ring"] = "mask" if support.any() else "ring"
        self.support = support if self.source == "mask" else ring_mask(illusion, ring_thickness)
        covered = int(np.count_nonzero(self.support & illusion))
        self.overlap = covered / max(int(np.count_nonzero(self.support)), 1)

    def report(self, status: Status, reason: str | None, **figures: object) -> PairReport:
        return PairReport(
            index=self.index,
            status=status,
            reason=reason,
            illusion_px=int(np.count_nonzero(self.illusion)),
            support_px=int(np.count_nonzero(self.support)),
            support_source=self.source,
            overlap=round(self.overlap, 6),
            **figures,  # type: ignore[arg-type]
        )


@dataclass(frozen=True)
class _FitSettings:
    threshold: float
    hypotheses: int
    seed: int
    min_area: int
    max_overlap: float
    low: float  # disparity = low + span · normalised
    span: float


def _rectify_pair(pair: _Pair, normalised: np.ndarray, out: np.ndarray, fit: _FitSettings) -> PairReport:
    """Fit the pair's support plane and write it into ``out`` (normalised units) in place."""
    where = f"pair #{pair.index}"
    illusion_px = int(np.count_nonzero(pair.illusion))
    if illusion_px < fit.min_area:
        raise InputError(f"{where}: illusion mask has {illusion_px} px (< {fit.min_area}); skipped")
    if pair.overlap > fit.max_overlap:
        raise UnreliableSupportError(
            f"{where}: {pair.overlap:.0%} of the support is covered by the illusion (> {fit.max_overlap:.0%})"
        )
    usable = pair.support & ~pair.illusion & np.isfinite(normalised)
    rows, cols = np.nonzero(usable)
    if len(rows) < fit.min_area:
        raise InputError(f"{where}: support has {len(rows)} usable px (< {fit.min_area}); skipped")
    points = np.column_stack([cols, rows, normalised[rows, cols]]).astype(np.float64)
    try:
        plane_fit = fit_plane_ransac(points, fit.threshold, fit.hypotheses, fit.seed)
        ill_rows, ill_cols = np.nonzero(pair.illusion)
        out[ill_rows, ill_cols] = plane_fit.disparity_at(ill_cols, ill_rows)
    except DegenerateSupportError as exc:
        raise DegenerateSupportError(f"{where}: {exc}") from None
    low, span = fit.low, fit.span
    alpha, beta, delta, gamma = plane_fit.params
    # In disparity units: α·u + β·v + (δ/span)·d + (γ − δ·low/span) = 0, renormalised.
    plane = np.array([alpha, beta, delta / span, gamma - delta * low / span])
    plane /= np.linalg.norm(plane[:3])
    return pair.report(
        "rectified",
        None,
        inlier_ratio=round(plane_fit.inlier_ratio, 6),
        # Point-to-plane distance / δ is the vertical (disparity) residual.
        residual=float(plane_fit.residual / delta * span),
        plane=tuple(float(p) for p in plane),
    )


def ring_mask(illusion: np.ndarray, thickness: int) -> np.ndarray:
    """The ``thickness``-px ring (bool HxW) just outside ``illusion``: a stand-in support."""
    return _dilate(illusion, thickness) & ~illusion


def _seam_weight(region: np.ndarray, radius: int) -> np.ndarray:
    """Blend weight (float HxW) of the smoothed values: 1 on the region's boundary, falling
    linearly to 0 at ``radius`` px on either side, so the band itself leaves no seam."""
    if not region.any() or region.all():
        return np.zeros(region.shape)
    as_u8 = region.astype(np.uint8)
    inside = cv2.distanceTransform(as_u8, cv2.DIST_L2, 5)
    outside = cv2.distanceTransform(1 - as_u8, cv2.DIST_L2, 5)
    # Boundary pixels are 1 px from the other side on either side of the edge.
    distance = np.where(region, inside, outside) - 1
    return np.clip(1 - distance / radius, 0, 1)


def _disk(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def _dilate(region: np.ndarray, radius: int) -> np.ndarray:
    return cv2.dilate(region.astype(np.uint8), _disk(radius)).astype(bool)
